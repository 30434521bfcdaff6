#include "server/create_reactor.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <system_error>
#include <thread>
#include <utility>

#include <sys/resource.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "mesh/vertex_order.h"
#include "preprocess/preprocess.h"
#include "server/filigree_service.h"
#include "server/resident_memory.h"
#include "server/stream_writer.h"
#include "util/time_left.h"
#include "skinning/rig_file.h"

namespace filigree::server {
namespace {

// What an upload's buffer starts with; it grows as bytes arrive.
constexpr std::uint64_t kInitialUploadBuffer = 4 << 20;

// Nice value of preprocessing threads (sessions' frames run at 0).
constexpr int kPreprocessingNice = 10;

// Whether some triangle of `mesh` has an area (above rounding of its
// coordinates): a mesh of only zero-area faces has nothing to deform.
bool has_area(const TriMesh& mesh) {
  const double size = bounding_box_diagonal(mesh.positions);
  for (const Triangle& f : mesh.faces) {
    const Vec3 a = mesh.positions[f[0]], b = mesh.positions[f[1]], c = mesh.positions[f[2]];
    if ((b - a).cross(c - a).norm() > 1e-12 * size * size) return true;
  }
  return false;
}

std::string seconds(double s) {
  std::ostringstream out;
  out << s;
  return out.str();
}

class CreateReactor final : public grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse> {
 public:
  CreateReactor(FiligreeService& service, grpc::CallbackServerContext* context) : service_(service), writer_(this) {
    // Who may create, and how much, is settled before any byte is read.
    const ApiKey* key = nullptr;
    grpc::Status status = service_.check_api_key(*context, &keys_, &key);
    if (status.ok() && key) status = service_.admit_upload(*key, &pending_);
    if (status.ok()) status = service_.admit_memory();
    if (!status.ok()) {
      writer_.finish(status);
      return;
    }
    key_ = key;
    service_.track_upload(this, [this] {
      // Not while OnReadDone handles a message: no read may start after Finish.
      std::lock_guard lock(read_mutex_);
      expired_ = true;  // before finish: the read it ends must not start processing
      writer_.finish({grpc::StatusCode::DEADLINE_EXCEEDED,
                      "the upload did not arrive within the server's " + seconds(service_.limits().upload_seconds) +
                          " s (--upload-timeout); " + std::to_string(bytes_.size()) + " bytes came"});
    });
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    std::unique_lock lock(read_mutex_);
    if (expired_) return;
    if (!ok) {  // the client half-closed: the upload is complete
      if (!begun_) return writer_.finish({grpc::StatusCode::INVALID_ARGUMENT, "the upload sent no 'begin' message"});
      lock.unlock();  // start_processing takes the uploads' lock, which expiry holds before this one
      return start_processing();
    }
    if (request_.has_begin()) {
      if (begun_) return writer_.finish({grpc::StatusCode::INVALID_ARGUMENT, "'begin' sent twice"});
      begin_ = request_.begin();
      begun_ = true;
      if (begin_.total_bytes() > service_.limits().max_mesh_bytes)
        return writer_.finish({grpc::StatusCode::RESOURCE_EXHAUSTED, too_large(begin_.total_bytes())});
      if (const grpc::Status options = check_options(begin_.options()); !options.ok()) return writer_.finish(options);
      // A proposed id is checked now, not after seconds of preprocessing (create() checks it again).
      if (const grpc::Status id_status = check_proposed_id(begin_.session_id()); !id_status.ok())
        return writer_.finish(id_status);
      if (const grpc::Status memory = service_.reserve_upload_memory(begin_.total_bytes(), &memory_); !memory.ok())
        return writer_.finish(memory);
      // Grown as bytes arrive: a Begin alone holds no memory (a hundred
      // silent 256 MiB Begins reserved 26 GiB of address space).
      bytes_.reserve(std::min<std::uint64_t>(begin_.total_bytes(), kInitialUploadBuffer));
    } else {
      if (!begun_) return writer_.finish({grpc::StatusCode::INVALID_ARGUMENT, "the first message must be 'begin'"});
      if (request_.chunk().size() > begin_.total_bytes() - bytes_.size())
        return writer_.finish({grpc::StatusCode::INVALID_ARGUMENT, "the upload sends more than the " +
                                                                       std::to_string(begin_.total_bytes()) +
                                                                       " bytes its 'begin' declared (total_bytes)"});
      bytes_ += request_.chunk();
    }
    StartRead(&request_);
  }

  void OnWriteDone(bool ok) override { writer_.on_write_done(ok); }
  // The client cancelled, or its deadline passed: preprocessing stops at
  // its next check, its turn and memory are freed, and no session is made.
  void OnCancel() override {
    cancelled_ = true;  // before finish: a session made after this is not made, or closed again
    stop_ = true;
    writer_.finish(grpc::Status::CANCELLED);
  }
  void OnDone() override {
    service_.untrack_upload(this);
    // gRPC may run OnDone on the job's own thread (Finish called from it).
    if (job_.joinable()) job_.get_id() == std::this_thread::get_id() ? job_.detach() : job_.join();
    delete this;
  }

 private:
  std::string too_large(std::uint64_t n) const {
    return "mesh of " + std::to_string(n) + " bytes is over the server's limit of " +
           std::to_string(service_.limits().max_mesh_bytes) + " bytes (--max-mesh-bytes)";
  }

  // What the upload's options say, checked before any byte of the mesh is
  // read: a wrong option is refused, never silently replaced by a default.
  static grpc::Status check_options(const v1::SessionOptions& o) {
    if (o.quantization_bits() != 0 && (o.quantization_bits() < 8 || o.quantization_bits() > 24))
      return {grpc::StatusCode::INVALID_ARGUMENT, "quantization_bits must be between 8 and 24"};
    if (!(o.threshold() >= 0.0) || std::isinf(o.threshold()))
      return {grpc::StatusCode::INVALID_ARGUMENT, "threshold must be a finite number ≥ 0 (whole_mesh for ∞)"};
    if (!(o.regions_budget_ms() >= 0.0) || std::isinf(o.regions_budget_ms()))
      return {grpc::StatusCode::INVALID_ARGUMENT, "regions_budget_ms must be a finite number of ms ≥ 0"};
    if (o.regions_budget_ms() > 0.0 && o.whole_mesh())
      return {grpc::StatusCode::INVALID_ARGUMENT, "whole_mesh optimises the whole mesh: it has no regions' budget"};
    if (!v1::SkinningMethod_IsValid(o.skinning()))
      return {grpc::StatusCode::INVALID_ARGUMENT, "skinning method " + std::to_string(o.skinning()) + " is unknown"};
    // 0 is "not set"; otherwise a share of the vertices.
    if (!(o.base_ratio() >= 0.0 && o.base_ratio() <= 1.0))
      return {grpc::StatusCode::INVALID_ARGUMENT, "base_ratio must be a number in (0, 1], or 0 for the default"};
    return grpc::Status::OK;
  }

  grpc::Status check_proposed_id(const std::string& id) {
    if (id.empty()) return grpc::Status::OK;
    if (!is_session_id(id))
      return {grpc::StatusCode::INVALID_ARGUMENT, "a proposed session id is " + std::to_string(kSessionIdLength) +
                                                      " lowercase hex digits, not " + printable_session_id(id)};
    try {
      if (service_.registry().taken(id)) return {grpc::StatusCode::ALREADY_EXISTS, "the proposed session id is taken"};
    } catch (const StoreUnavailable& e) {
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    }
    return grpc::Status::OK;
  }

  // Why preprocessing stopped (stop_): the client gave up, or the server is draining.
  grpc::Status stopped() const {
    if (cancelled_) return grpc::Status::CANCELLED;
    return {grpc::StatusCode::UNAVAILABLE, "the server is shutting down: upload again once it is back"};
  }

  // `seconds_left`: the stage's estimate, 0 for none.
  void progress(const char* stage, double fraction, double seconds_left = 0.0) {
    v1::CreateSessionResponse r;
    r.mutable_progress()->set_stage(stage);
    r.mutable_progress()->set_fraction(fraction);
    r.mutable_progress()->set_seconds_left(seconds_left);
    writer_.send(std::make_shared<const v1::CreateSessionResponse>(std::move(r)), /*droppable=*/true);
  }

  // Parsing and preprocessing can take seconds: never on a gRPC thread.
  void start_processing() {
    service_.untrack_upload(this);  // its bytes are in: preprocessing is not limited by --upload-timeout
    if (expired_) return;           // expired while untracking
    if (!service_.begin_job()) return writer_.finish({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
    try {
      job_ = std::thread([this] {
        // Live sessions' frames come first: preprocessing runs at a lower
        // priority (threads it starts inherit it), a bounded number at once.
        ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), kPreprocessingNice);
        service_.watch_preprocessing(&stop_);  // a server draining stops it too
        service_.acquire_preprocessing();
        // One that gave up (or a server stopping) while it waited its turn starts nothing.
        const grpc::Status status = stop_ ? stopped() : process();
        service_.release_preprocessing();
        service_.unwatch_preprocessing(&stop_);
        // Parsing, repair and preprocessing free tens to hundreds of MB that
        // glibc would otherwise keep in this thread's arena: give them back, so
        // the server's resident memory is what its sessions hold.
        release_free_memory();
        service_.end_job();
        writer_.finish(status);  // the last touch of this reactor from the job
      });
    } catch (const std::system_error& e) {
      service_.end_job();
      writer_.finish({grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("the server could not start a thread: ") + e.what()});
    }
  }

  grpc::Status process() {
    try {
      progress("validating", 0.0);
      RiggedMesh upload = read_rigged_mesh_from_memory(bytes_, begin_.format());
      const TriMesh& input = upload.mesh;
      // Before any preprocessing (the proto's Begin says so).
      if (input.vertex_count() > service_.limits().max_vertices)
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "mesh has " + std::to_string(input.vertex_count()) +
                                                          " vertices, over the server's limit of " +
                                                          std::to_string(service_.limits().max_vertices) +
                                                          " (--max-vertices)"};
      if (stop_) return stopped();
      RepairReport repair;
      const TriMesh repaired = repair_mesh(input, {}, &repair);
      if (!has_area(repaired))
        return {grpc::StatusCode::INVALID_ARGUMENT, "the mesh has no triangle with an area: all " +
                                                        std::to_string(input.face_count()) + " faces are degenerate"};
      // Sessions order vertices along a space-filling curve: frames then
      // compress to about half the size, and recovery reads memory in order.
      // SessionInfo.rest.uploaded_ids states the mapping to the upload.
      std::shared_ptr<void> vertices_reserved;  // until the registry counts the session
      if (key_) {
        if (const grpc::Status quota = service_.reserve_vertices(*key_, repaired.vertex_count(), &vertices_reserved);
            !quota.ok())
          return quota;
      }
      const std::vector<Index> order = locality_order(repaired.positions);
      const TriMesh mesh = permute_vertices(repaired, order);
      std::vector<Index> uploaded_ids(order.size());
      for (std::size_t i = 0; i < order.size(); ++i) uploaded_ids[i] = repair.new_to_old_vertex[order[i]];

      const v1::SessionOptions& o = begin_.options();
      PreprocessOptions pre;
      if (o.base_vertices() > 0) pre.base_vertices = o.base_vertices();
      if (o.base_ratio() > 0.0) pre.ratio = o.base_ratio();
      pre.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
      pre.stop = &stop_;  // cancelled, past its deadline, or the server draining
      // The one long stage: its progress says the time left.
      pre.progress = [this, since = std::chrono::steady_clock::now(), left = TimeLeft()](double f) mutable {
        left.add(std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count(), f);
        progress("simplifying", f, left.seconds().value_or(0.0));
      };

      std::string key;
      bool built = false;
      auto h = service_.cache().get_or_build(mesh, pre, &key, &built);
      progress("starting", 1.0);
      // A skinned upload keeps its rig for the base vertices: base vertex k
      // is session vertex base_vertices[k], which is uploaded vertex uploaded_ids[…].
      std::string rig;
      if (upload.rig) {
        std::vector<Index> base_uploaded(h->base_vertices.size());
        for (std::size_t k = 0; k < base_uploaded.size(); ++k) base_uploaded[k] = uploaded_ids[h->base_vertices[k]];
        rig = serialize_rig(upload.rig->restricted_to(base_uploaded));
      }
      // A client that gave up gets no session: nobody would hold its tokens.
      if (cancelled_) return grpc::Status::CANCELLED;
      auto session = service_.registry().create(h, key, o, std::move(uploaded_ids), begin_.session_id(), std::move(rig),
                                                key_ ? key_->name : std::string());
      pending_.reset();  // a session now: counted by the registry
      memory_.reset();   // and in the resident memory
      if (cancelled_) {  // it gave up while the session was made
        service_.registry().close(session->id());
        return grpc::Status::CANCELLED;
      }
      v1::CreateSessionResponse r;
      auto* created = r.mutable_created();
      *created->mutable_info() = session->info(service_.limits().inline_rest_bytes());
      const SessionRecord record = session->record();
      created->set_editor_token(record.editor_token);
      created->set_viewer_token(record.viewer_token);
      created->set_cached(!built);
      writer_.send(std::make_shared<const v1::CreateSessionResponse>(std::move(r)), /*droppable=*/false);
      spdlog::info("event=upload_done session={} bytes={} vertices={} cached={}", session->id(), bytes_.size(),
                   mesh.vertex_count(), !built);
      return grpc::Status::OK;
    } catch (const PreprocessingStopped&) {
      return stopped();
    } catch (const BadSessionId& e) {
      return {e.taken ? grpc::StatusCode::ALREADY_EXISTS : grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const MeshIoError& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const InvalidMeshError& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const std::invalid_argument& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const TooManySessions& e) {
      return {grpc::StatusCode::RESOURCE_EXHAUSTED, e.what()};
    } catch (const StoreUnavailable& e) {
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    } catch (const std::exception& e) {
      spdlog::error("event=upload_failed error=\"{}\"", e.what());
      return {grpc::StatusCode::INTERNAL, e.what()};
    }
  }

  FiligreeService& service_;
  std::shared_ptr<const ApiKeys> keys_;  // keeps key_ alive across a reload
  const ApiKey* key_ = nullptr;          // null: no keys configured
  std::shared_ptr<void> pending_;        // this upload in its key's session quota until it is a session
  std::shared_ptr<void> memory_;         // its declared bytes under --max-memory until it is a session
  StreamWriter<CreateReactor, v1::CreateSessionResponse> writer_;
  v1::CreateSessionRequest request_;
  v1::CreateSessionRequest::Begin begin_;
  bool begun_ = false;
  std::atomic<bool> cancelled_{false};
  std::atomic<bool> stop_{false};  // PreprocessOptions::stop: cancelled_, or the server draining
  std::string bytes_;
  std::thread job_;
  std::mutex read_mutex_;  // OnReadDone against expiry (--upload-timeout)
  bool expired_ = false;   // under read_mutex_, except once reads are over
};

}  // namespace

grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse>* new_create_reactor(
    FiligreeService& service, grpc::CallbackServerContext* context) {
  return new CreateReactor(service, context);
}

}  // namespace filigree::server
