#include "server/filigree_service.h"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
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
#include "runtime/pose.h"
#include "server/resident_memory.h"
#include "server/stream_writer.h"
#include "skinning/animation_clip.h"
#include "skinning/rig_file.h"

namespace filigree::server {
namespace {

std::string metadata(const grpc::CallbackServerContext& context, const char* key) {
  const auto& md = context.client_metadata();
  const auto it = md.find(key);
  return it == md.end() ? std::string() : std::string(it->second.data(), it->second.size());
}

// A DriveRequest's pose: positions (full or partial) or joints, not both.
// request_keyframe goes with the pose: the frame that includes it is a keyframe.
void submit_pose(Session& session, std::uint64_t driver, const v1::DriveRequest& r) {
  if (r.request_keyframe() && r.positions().empty() && r.indices().empty() && !r.has_joints())
    return session.request_keyframe();  // only the keyframe request: no pose to merge
  const PoseOrigin origin{driver, r.client_name(), r.pose_id(), r.request_keyframe()};
  if (r.has_joints()) {
    if (!r.positions().empty() || !r.indices().empty())
      throw PoseError("a pose gives positions or joints, not both");
    return session.submit_joints(origin, r.joints());
  }
  session.submit(origin, {r.indices().data(), static_cast<std::size_t>(r.indices().size())},
                 {r.positions().data(), static_cast<std::size_t>(r.positions().size())});
}

grpc::Status no_such_session(const std::string& id) {
  return {grpc::StatusCode::NOT_FOUND, "no session " + printable_session_id(id) + " for these credentials"};
}

grpc::ServerUnaryReactor* finish_unary(grpc::CallbackServerContext* context, const grpc::Status& status) {
  auto* reactor = context->DefaultReactor();
  reactor->Finish(status);
  return reactor;
}

}  // namespace

grpc::Status authorize(SessionRegistry& registry, grpc::CallbackServerContext& context, const std::string& id,
                       Role needed, std::shared_ptr<Session>* session) {
  const std::string session_id = id.empty() ? metadata(context, "x-session-id") : id;
  if (session_id.empty()) return {grpc::StatusCode::INVALID_ARGUMENT, "no session id (field session_id or x-session-id metadata)"};
  // Before any lookup: a call without a token learns nothing of the session.
  const std::string token = metadata(context, "x-filigree-token");
  if (token.empty()) return {grpc::StatusCode::UNAUTHENTICATED, "missing x-filigree-token metadata"};
  // A client that routes itself does not pull sessions to the replica it calls.
  const bool take_over = metadata(context, "x-filigree-route") != "direct";
  try {
    *session = registry.find(session_id, take_over);
  } catch (const SessionElsewhere& e) {
    if (!e.owner_address.empty()) context.AddTrailingMetadata("x-filigree-owner", e.owner_address);
    context.AddTrailingMetadata("x-filigree-retry-after-ms", std::to_string(e.retry_after_ms));
    // A client routing itself must call the owner: gRPC's own retries of this replica would not help.
    if (!take_over && !e.owner_address.empty()) context.AddTrailingMetadata("grpc-retry-pushback-ms", "-1");
    return {grpc::StatusCode::UNAVAILABLE, e.what()};
  } catch (const StoreUnavailable& e) {
    return {grpc::StatusCode::UNAVAILABLE, e.what()};
  } catch (const SessionUnusable& e) {
    return {grpc::StatusCode::DATA_LOSS, e.what()};
  }
  // "No such session" and "not yours" are one answer: it does not tell
  // whether an id exists.
  const Role role = *session ? (*session)->authorize(token) : Role::kNone;
  if (role == Role::kNone) {
    session->reset();
    return no_such_session(session_id);
  }
  if (needed == Role::kEditor && role != Role::kEditor)
    return {grpc::StatusCode::PERMISSION_DENIED, "a viewer token cannot change session " + session_id};
  return grpc::Status::OK;
}

void FiligreeService::with_session(grpc::CallbackServerContext& context, const std::string& id, Role needed,
                                   SessionContinuation then) {
  const std::string session_id = id.empty() ? metadata(context, "x-session-id") : id;
  if (session_id.empty() || registry_.in_memory(session_id)) {
    std::shared_ptr<Session> s;
    const grpc::Status status = authorize(registry_, context, id, needed, &s);
    return then(status, std::move(s));
  }
  // Shared: if the job cannot start, `then` still answers the call.
  auto next = std::make_shared<SessionContinuation>(std::move(then));
  run_job(
      [this, &context, id, needed, next] {
        // A turn: a failover or a restart's first requests must not load every
        // session at once (each load's memory, all of them slowed alike).
        loads_.acquire();
        std::shared_ptr<Session> s;
        grpc::Status status;
        try {
          status = authorize(registry_, context, id, needed, &s);
        } catch (const std::exception& e) {  // off a gRPC thread an escaped exception would end the process
          status = {grpc::StatusCode::INTERNAL, std::string("loading the session failed: ") + e.what()};
        }
        loads_.release();
        (*next)(status, std::move(s));
      },
      [next](const grpc::Status& why) { (*next)(why, nullptr); });
}

grpc::ServerUnaryReactor* FiligreeService::unary_on_session(grpc::CallbackServerContext* context, const std::string& id,
                                                            Role needed, std::function<grpc::Status(Session&)> body,
                                                            std::function<bool(const Session&)> slow) {
  auto* reactor = context->DefaultReactor();
  with_session(*context, id, needed,
               [this, reactor, body = std::move(body), slow = std::move(slow)](grpc::Status status, std::shared_ptr<Session> s) mutable {
    auto answer = [reactor, body = std::move(body)](grpc::Status status, std::shared_ptr<Session> s) {
      if (status.ok()) {
        try {
          status = body(*s);
        } catch (const std::exception& e) {  // off a gRPC thread an escaped exception would end the process
          status = {grpc::StatusCode::INTERNAL, e.what()};
        }
      }
      s.reset();  // before the call ends, so that a session closed meanwhile ends here
      reactor->Finish(status);
    };
    if (!status.ok() || !slow || !slow(*s)) return answer(status, std::move(s));
    run_job([answer = std::move(answer), s = std::move(s)]() mutable { answer(grpc::Status::OK, std::move(s)); },
            [reactor](const grpc::Status& why) { reactor->Finish(why); });
  });
  return reactor;
}

FiligreeService::FiligreeService(SessionRegistry& registry, HierarchyCache& cache, ServiceLimits limits)
    : registry_(registry), cache_(cache), limits_(limits), preprocessing_(limits.preprocessing_slots),
      loads_(limits.session_loads ? limits.session_loads : std::thread::hardware_concurrency()) {}

FiligreeService::~FiligreeService() { drain(); }

void FiligreeService::set_api_keys(std::shared_ptr<const ApiKeys> keys) {
  std::lock_guard lock(keys_mutex_);
  keys_ = std::move(keys);
}

std::shared_ptr<const ApiKeys> FiligreeService::api_keys() const {
  std::lock_guard lock(keys_mutex_);
  return keys_;
}

grpc::Status FiligreeService::check_api_key(const grpc::CallbackServerContext& context,
                                            std::shared_ptr<const ApiKeys>* keys, const ApiKey** key) const {
  *keys = api_keys();
  *key = nullptr;
  if (!*keys) return grpc::Status::OK;
  const std::string presented = metadata(context, "x-filigree-api-key");
  if (presented.empty())
    return {grpc::StatusCode::UNAUTHENTICATED, "this server needs an API key (x-filigree-api-key metadata) to create or list sessions"};
  *key = (*keys)->find(presented);
  if (!*key) return {grpc::StatusCode::PERMISSION_DENIED, "the API key is not one this server knows"};
  return grpc::Status::OK;
}

namespace {

grpc::Status sessions_quota_exhausted(const ApiKey& key) {
  return {grpc::StatusCode::RESOURCE_EXHAUSTED, "API key '" + key.name + "' holds its quota of " +
                                                    std::to_string(key.quota.sessions) +
                                                    " sessions (uploads in progress included)"};
}

}  // namespace

grpc::Status FiligreeService::admit_upload(const ApiKey& key, std::shared_ptr<void>* pending) {
  pending->reset();
  std::shared_ptr<void> place;
  if (key.quota.sessions != 0) {
    // Uploads admitted but not yet sessions take a place too: concurrent
    // uploads of one key cannot all pass the same check.
    place = uploading_.take(key.name, key.quota.sessions, 1, [&] { return registry_.holdings(key.name).sessions; });
    if (!place) return sessions_quota_exhausted(key);
  }
  if (!ledger_.admit_upload(key.name, key.quota.uploads_per_minute))
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "API key '" + key.name + "' made its quota of " +
                                                      std::to_string(key.quota.uploads_per_minute) + " uploads in the last minute"};
  *pending = std::move(place);
  return grpc::Status::OK;
}

grpc::Status FiligreeService::reserve_vertices(const ApiKey& key, std::uint64_t vertices, std::shared_ptr<void>* reserved) {
  reserved->reset();
  if (key.quota.vertices == 0) return grpc::Status::OK;
  std::uint64_t held = 0;
  *reserved = vertices_.take(key.name, key.quota.vertices, vertices, [&] { return held = registry_.holdings(key.name).vertices; });
  if (!*reserved)
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "API key '" + key.name + "' may hold " + std::to_string(key.quota.vertices) +
                                                      " vertices; its sessions hold " + std::to_string(held) +
                                                      ", with its other uploads in progress too many for this mesh of " +
                                                      std::to_string(vertices)};
  return grpc::Status::OK;
}

grpc::Status FiligreeService::open_stream(const Session& session, std::shared_ptr<void>* slot) {
  slot->reset();
  std::shared_ptr<void> place = stream_places_.take(session.id(), limits_.max_streams_per_session);
  if (!place)
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "session " + session.id() + " serves its maximum of " +
                                                      std::to_string(limits_.max_streams_per_session) +
                                                      " streams (--max-streams-per-session)"};
  const std::shared_ptr<const ApiKeys> keys = api_keys();
  if (!keys || session.owner().empty()) {
    *slot = std::move(place);
    return grpc::Status::OK;
  }
  const ApiKey* key = keys->by_name(session.owner());
  // A key revoked since (SIGHUP): its sessions open no new streams. (Taking
  // "no key" for "no quota" lifted the limit of a revoked key's sessions.)
  if (!key)
    return {grpc::StatusCode::PERMISSION_DENIED, "the API key that created session " + session.id() +
                                                     " was revoked: its sessions take no new streams"};
  const std::uint64_t limit = key->quota.streams;
  std::shared_ptr<void> quota = ledger_.open_stream(session.owner(), limit);
  if (!quota)
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "the sessions of API key '" + session.owner() + "' have their quota of " +
                                                      std::to_string(limit) + " streams open"};
  // One slot holds both: released together when the stream ends.
  *slot = std::make_shared<std::pair<std::shared_ptr<void>, std::shared_ptr<void>>>(std::move(place), std::move(quota));
  return grpc::Status::OK;
}

bool FiligreeService::begin_job() {
  std::lock_guard lock(jobs_mutex_);
  if (draining_) return false;
  ++jobs_;
  return true;
}

void FiligreeService::end_job() {
  std::lock_guard lock(jobs_mutex_);
  if (--jobs_ == 0) jobs_done_.notify_all();
}

void FiligreeService::run_job(std::function<void()> work, const std::function<void(const grpc::Status&)>& refused) {
  if (!begin_job()) return refused({grpc::StatusCode::UNAVAILABLE, "the server is shutting down"});
  try {
    std::thread([this, work = std::move(work)]() mutable {
      work();
      work = nullptr;  // what it holds may need the service: released while the service surely exists
      end_job();       // the last touch of the service: drain() waits for it
    }).detach();
  } catch (const std::system_error& e) {
    end_job();
    refused({grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("the server could not start a thread: ") + e.what()});
  }
}

void FiligreeService::acquire_preprocessing() { preprocessing_.acquire(); }

void FiligreeService::release_preprocessing() { preprocessing_.release(); }

std::size_t FiligreeService::loads_waiting() const { return loads_.waiting(); }

grpc::Status FiligreeService::admit_memory() {
  if (limits_.max_memory_bytes == 0) return grpc::Status::OK;
  const auto under = [&] { return resident_bytes() < limits_.max_memory_bytes; };
  if (under()) return grpc::Status::OK;
  // One eviction at a time: uploads arriving meanwhile wait for it and then
  // see what it freed, rather than each evicting (and trimming) on its own.
  std::lock_guard evicting(evict_mutex_);
  if (under()) return grpc::Status::OK;
  const std::size_t evicted = registry_.evict_idle_until([&] {
    release_free_memory();
    return under();
  });
  if (under()) {
    spdlog::info("event=memory_reclaimed evicted_sessions={}", evicted);
    return grpc::Status::OK;
  }
  constexpr std::uint64_t kMiB = 1 << 20;
  return {grpc::StatusCode::RESOURCE_EXHAUSTED,
          "the server is at its memory limit: " + std::to_string(resident_bytes() / kMiB) + " MiB resident of " +
              std::to_string(limits_.max_memory_bytes / kMiB) + " MiB (--max-memory) after evicting " +
              std::to_string(evicted) + " idle sessions; sessions in use stay. Try later or another server"};
}

grpc::Status FiligreeService::reserve_upload_memory(std::uint64_t bytes, std::shared_ptr<void>* reserved) {
  reserved->reset();
  if (limits_.max_memory_bytes == 0) return grpc::Status::OK;
  std::lock_guard lock(upload_memory_mutex_);
  // Resident memory already holds what uploads received so far: counted
  // twice, on the safe side.
  const std::uint64_t resident = resident_bytes();
  if (resident + upload_memory_reserved_ + bytes > limits_.max_memory_bytes) {
    constexpr std::uint64_t kMiB = 1 << 20;
    return {grpc::StatusCode::RESOURCE_EXHAUSTED,
            "an upload of " + std::to_string(bytes / kMiB) + " MiB does not fit: the server holds " +
                std::to_string(resident / kMiB) + " MiB and uploads in progress reserve " +
                std::to_string(upload_memory_reserved_ / kMiB) + " MiB of its " + std::to_string(limits_.max_memory_bytes / kMiB) +
                " MiB (--max-memory). Try later or another server"};
  }
  upload_memory_reserved_ += bytes;
  *reserved = std::shared_ptr<void>(static_cast<void*>(this), [this, bytes](void*) {
    std::lock_guard lock(upload_memory_mutex_);
    upload_memory_reserved_ -= bytes;
  });
  return grpc::Status::OK;
}

void FiligreeService::track_upload(const void* upload, std::function<void()> expire) {
  if (limits_.upload_seconds <= 0) return;
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(limits_.upload_seconds));
  std::lock_guard lock(uploads_mutex_);
  uploads_[upload] = Upload{deadline, std::move(expire)};
}

void FiligreeService::untrack_upload(const void* upload) {
  std::lock_guard lock(uploads_mutex_);
  uploads_.erase(upload);
}

void FiligreeService::expire_uploads() {
  const auto now = std::chrono::steady_clock::now();
  // Under the lock: an upload untracks itself (under it) before it is deleted.
  std::lock_guard lock(uploads_mutex_);
  for (auto it = uploads_.begin(); it != uploads_.end();) {
    if (it->second.deadline > now) {
      ++it;
      continue;
    }
    it->second.expire();
    it = uploads_.erase(it);
  }
}

void FiligreeService::drain() {
  // Preprocessing in progress stops at its next check: a pathological mesh
  // cannot hold a shutdown (its upload, not yet a session, is refused).
  stop_preprocessing_ = true;
  std::unique_lock lock(jobs_mutex_);
  draining_ = true;
  jobs_done_.wait(lock, [&] { return jobs_ == 0; });
}

// ------------------------------------------------------------ CreateSession

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
  void OnCancel() override {
    cancelled_ = true;  // before finish: a session made after this is not made, or closed again
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

  void progress(const char* stage, double fraction) {
    v1::CreateSessionResponse r;
    r.mutable_progress()->set_stage(stage);
    r.mutable_progress()->set_fraction(fraction);
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
        service_.acquire_preprocessing();
        const grpc::Status status = process();
        service_.release_preprocessing();
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
      if (input.vertex_count() > service_.limits().max_vertices)
        return {grpc::StatusCode::RESOURCE_EXHAUSTED, "mesh has " + std::to_string(input.vertex_count()) +
                                                          " vertices, over the server's limit of " +
                                                          std::to_string(service_.limits().max_vertices)};
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
      pre.stop = &service_.preprocessing_stop();
      pre.progress = [this](double f) { progress("simplifying", f); };

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
      *created->mutable_info() = session->info();
      const SessionRecord record = session->record();
      created->set_editor_token(record.editor_token);
      created->set_viewer_token(record.viewer_token);
      created->set_cached(!built);
      writer_.send(std::make_shared<const v1::CreateSessionResponse>(std::move(r)), /*droppable=*/false);
      spdlog::info("event=upload_done session={} bytes={} vertices={} cached={}", session->id(), bytes_.size(),
                   mesh.vertex_count(), !built);
      return grpc::Status::OK;
    } catch (const PreprocessingStopped&) {
      return {grpc::StatusCode::UNAVAILABLE, "the server is shutting down: upload again once it is back"};
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
  std::string bytes_;
  std::thread job_;
  std::mutex read_mutex_;  // OnReadDone against expiry (--upload-timeout)
  bool expired_ = false;   // under read_mutex_, except once reads are over
};

// ------------------------------------------------------------ Drive, Watch

// The streaming methods are raw (their frames go out serialized once, see
// serialized_frame.h), and so are JoinSession and SetOptions (their meshes,
// session_info_wire.h), GetState (its frames) and GetOverlays, so their
// requests are parsed here; a request that is not a valid message is the
// caller's error.
template <class Message>
grpc::Status parse_request(const grpc::ByteBuffer& bytes, Message& out) {
  grpc::ByteBuffer copy(bytes);  // Deserialize consumes its buffer (a copy shares the slices)
  if (grpc::SerializationTraits<Message>::Deserialize(&copy, &out).ok()) return grpc::Status::OK;
  return {grpc::StatusCode::INVALID_ARGUMENT, "the request is not a valid " + out.GetTypeName() + " message"};
}

// A frame as one stream writes it: the frame's shared wire bytes (with the
// stream's pose id), and the version it has if it is a chunked keyframe.
struct OutgoingFrame {
  grpc::ByteBuffer bytes;
  std::uint64_t version = 0;
  std::optional<std::uint64_t> keyframe;
};
const grpc::ByteBuffer& wire(const OutgoingFrame& f) { return f.bytes; }

// The clip time of each sample a PlayClip stream submitted, by pose id. A
// sample is submitted once the previous one is shown, so frames name one of
// the newest few: older ones are forgotten.
class ClipTimes {
 public:
  void record(std::uint64_t pose_id, double seconds) {
    std::lock_guard lock(mutex_);
    times_.emplace_back(pose_id, seconds);
    if (times_.size() > kKept) times_.pop_front();
  }
  // 0 for a pose id not among the newest (none is, once shown).
  double of(std::uint64_t pose_id) const {
    std::lock_guard lock(mutex_);
    for (const auto& [id, seconds] : times_)
      if (id == pose_id) return seconds;
    return 0.0;
  }

 private:
  static constexpr std::size_t kKept = 4;
  mutable std::mutex mutex_;
  std::deque<std::pair<std::uint64_t, double>> times_;
};

// A stream of frames with a mailbox of one: offer() replaces what is waiting,
// so a slow client skips frames, and never blocks the session. In the chunked
// format, a frame whose keyframe this stream has not written goes after it:
// the keyframe is queued to be sent first (Frame.keyframe_version).
template <class Reactor>
class FrameStream : public FrameSink {
 public:
  FrameStream(Reactor* reactor, std::uint64_t driver) : writer_(reactor), driver_(driver) {
    writer_.on_start_write([this](const OutgoingFrame& f) {
      if (f.keyframe) written_keyframe_ = *f.keyframe;
      // Only a stream that acknowledges keeps what it wrote: on Drive and
      // Watch nothing would ever take it off again.
      if (!acknowledged_) return;
      std::lock_guard lock(unread_mutex_);
      unread_.push_back(f.version);
    });
  }

  // Set once, before the stream subscribes (Follow): at most `window`
  // frames written and not acknowledged.
  void acknowledged_within(std::size_t window) {
    acknowledged_ = true;
    writer_.set_window(window);
  }

  // The client read every frame up to `version` (Follow): the frames written
  // at or below it leave the writer's window.
  void acknowledge(std::uint64_t version) {
    std::size_t read = 0;
    {
      std::lock_guard lock(unread_mutex_);
      // Written in version order, but a keyframe may go before an older
      // frame's place: count every written version at or below this one.
      for (auto it = unread_.begin(); it != unread_.end();)
        if (*it <= version) {
          it = unread_.erase(it);
          ++read;
        } else {
          ++it;
        }
    }
    if (read) writer_.release(read);
  }

  // Set once, before the stream subscribes.
  void set_format(v1::FrameFormat format) { format_ = format; }
  // Set once, before the stream subscribes (PlayClip): the clip time of
  // this stream's poses, written with the pose id into its frames.
  void set_clip_times(std::shared_ptr<const ClipTimes> times) { clip_times_ = std::move(times); }
  // Called after every offer (with the frame) and on close (with null);
  // set once, before the stream subscribes. Must not block.
  void on_event(std::function<void(const PublishedFrame*)> observer) { observer_ = std::move(observer); }
  v1::FrameFormat format() const override { return format_; }
  std::uint64_t driver() const override { return driver_; }

  void offer(std::shared_ptr<const PublishedFrame> frame) override {
    // The session offers from its workers and, once, from subscribe(): one at
    // a time, and never an older frame after a newer one.
    std::lock_guard lock(offer_mutex_);
    if (offered_any_ && frame->frame.version() <= offered_version_) return;
    offered_any_ = true;
    offered_version_ = frame->frame.version();
    write(frame);
    if (observer_) observer_(frame.get());
  }
  void close(bool session_closed, const std::string& why) override {
    writer_.finish(session_closed ? grpc::Status::OK : grpc::Status(grpc::StatusCode::UNAVAILABLE, why));
    if (observer_) observer_(nullptr);
  }
  StreamWriter<Reactor, OutgoingFrame>& writer() { return writer_; }

 private:
  void write(const std::shared_ptr<const PublishedFrame>& frame) {
    try {
      if (format_ == v1::FRAME_FORMAT_SINGLE) {
        if (frame->single) writer_.send(outgoing(*frame, *frame->single, frame->single_bytes()), /*droppable=*/true);
        return;
      }
      const PublishedFrame* key = frame->keyframe.get();
      if (key != nullptr) {
        const std::uint64_t version = key->frame.version();
        if (written_keyframe_ != version && queued_keyframe_ != version) {
          queued_keyframe_ = version;
          writer_.send(outgoing(*key, key->frame, key->frame_bytes()), /*droppable=*/false, /*supersede=*/true);
        }
      }
      writer_.send(outgoing(*frame, frame->frame, frame->frame_bytes()), /*droppable=*/true);
    } catch (const std::exception& e) {  // the frame could not be serialized: this stream cannot go on
      spdlog::error("event=frame_serialization_failed version={} error=\"{}\"", frame->frame.version(), e.what());
      writer_.finish({grpc::StatusCode::INTERNAL, std::string("a frame could not be serialized: ") + e.what()});
    }
  }

  // Every stream writes the frame's one serialized copy; a driver's also
  // names the newest of its poses the frame includes.
  std::shared_ptr<const OutgoingFrame> outgoing(const PublishedFrame& published, const v1::Frame& message,
                                                const SerializedFrame& bytes) const {
    std::uint64_t pose_id = 0;
    if (driver_)
      if (const auto it = published.pose_of_driver.find(driver_); it != published.pose_of_driver.end()) pose_id = it->second;
    auto out = std::make_shared<OutgoingFrame>();
    out->bytes = bytes.for_stream(pose_id, clip_times_ && pose_id ? clip_times_->of(pose_id) : 0.0);
    out->version = message.version();
    if (!message.chunks().empty() && message.keyframe_version() == message.version()) out->keyframe = message.version();
    return out;
  }

  StreamWriter<Reactor, OutgoingFrame> writer_;
  std::function<void(const PublishedFrame*)> observer_;
  std::shared_ptr<const ClipTimes> clip_times_;
  const std::uint64_t driver_;
  v1::FrameFormat format_ = v1::FRAME_FORMAT_SINGLE;
  // Versions of the keyframes written and queued; none yet (a keyframe may be version 0).
  static constexpr std::uint64_t kNone = ~std::uint64_t{0};
  std::atomic<std::uint64_t> written_keyframe_{kNone};
  std::mutex offer_mutex_;
  std::uint64_t queued_keyframe_ = kNone;  // offer_mutex_
  bool offered_any_ = false;               // offer_mutex_
  std::uint64_t offered_version_ = 0;
  std::atomic<bool> acknowledged_{false};  // a Follow stream
  std::mutex unread_mutex_;
  std::deque<std::uint64_t> unread_;  // versions written and not acknowledged (Follow)
};

// A frame stream's end (OnDone): it no longer subscribes or drives (a
// watcher's driver 0 drives nothing), and its writer never touches the
// reactor again.
template <class Reactor>
void leave(const std::shared_ptr<Session>& session, FrameStream<Reactor>& stream, std::uint64_t driver) {
  if (session) {
    session->unsubscribe(&stream);
    session->driver_left(driver);
  }
  stream.writer().detach();
}

// A stream's start while its session loads (FiligreeService::with_session,
// maybe on a job thread, which gRPC does not know of): until the start
// ends, nothing but the start may end the stream, since the reactor is
// deleted once it ends and the start still runs on it. A cancel that
// arrives meanwhile is held, and end_start() answers it. Shared, so that
// the start can end it after the reactor may be gone.
class StreamStart {
 public:
  void begin() {
    std::lock_guard lock(mutex_);
    starting_ = true;
  }
  bool cancelled() {
    std::lock_guard lock(mutex_);
    return cancelled_;
  }
  // The start is over: whether a cancel came while it ran.
  bool end() {
    std::lock_guard lock(mutex_);
    starting_ = false;
    return cancelled_;
  }
  // OnCancel: whether the caller may end the stream now (false while it starts).
  bool cancel() {
    std::lock_guard lock(mutex_);
    cancelled_ = true;
    return !starting_;
  }

 private:
  std::mutex mutex_;
  bool starting_ = false, cancelled_ = false;
};

// A stream's status once its session is there: CANCELLED if a cancel came
// meanwhile, else authorize()'s answer, else the session's stream limits
// (open_stream; *slot then holds the stream's place).
grpc::Status admit_stream(StreamStart& start, FiligreeService& service, const grpc::Status& authorized,
                          const std::shared_ptr<Session>& s, std::shared_ptr<void>* slot) {
  if (start.cancelled()) return grpc::Status::CANCELLED;
  if (!authorized.ok()) return authorized;
  return service.open_stream(*s, slot);
}

// A stream's start's last step: the stream ends with `status` if it is not
// OK, or as cancelled if a cancel came while it started. Touches only what it
// is given (the reactor may be gone once `start` ends; a finished writer
// ignores a second finish).
template <class Stream>
void end_start(const std::shared_ptr<StreamStart>& start, const std::shared_ptr<Stream>& stream, const grpc::Status& status) {
  const bool cancelled = start->end();
  if (!status.ok()) {
    stream->writer().finish(status);
  } else if (cancelled) {
    stream->writer().finish(grpc::Status::CANCELLED);
  }
}

// What the three frame streams (Drive, Watch, PlayClip) share: the stream
// with its mailbox, its start while the session loads, its place in the
// session's stream limits, and the session once admitted. open() loads and
// authorizes the session (FiligreeService::with_session), admits the stream
// (admit_stream) and hands the reactor's start() the result: OK with
// session_ set, or why not. start() must end with end_start(started, stream, …),
// now or later; until then the reactor is not deleted.
template <class Reactor, class Base>
class FrameStreamReactor : public Base {
 public:
  void OnWriteDone(bool ok) override { stream_->writer().on_write_done(ok); }
  void OnCancel() override {
    if (start_->cancel()) stream_->writer().finish(grpc::Status::CANCELLED);
  }
  // The stream no longer subscribes or drives (leave()), and the reactor is
  // deleted: the last thing it does.
  void OnDone() override {
    leave(session_, *stream_, driver_);
    delete static_cast<Reactor*>(this);
  }

 protected:
  // `self`: the reactor being made (the stream's writer calls it later).
  FrameStreamReactor(FiligreeService& service, std::uint64_t driver, Reactor* self)
      : service_(service), driver_(driver), stream_(std::make_shared<FrameStream<Reactor>>(self, driver)) {}

  void open(grpc::CallbackServerContext& context, const std::string& session_id, Role role) {
    start_->begin();
    service_.with_session(context, session_id, role, [this](grpc::Status status, std::shared_ptr<Session> s) {
      const auto started = start_;
      const auto stream = stream_;  // this reactor may end once the start does
      status = admit_stream(*started, service_, status, s, &stream_slot_);
      if (status.ok()) session_ = std::move(s);
      start(status, started, stream);
    });
  }
  virtual void start(const grpc::Status& admitted, const std::shared_ptr<StreamStart>& started,
                     const std::shared_ptr<FrameStream<Reactor>>& stream) = 0;

  FiligreeService& service_;
  const std::uint64_t driver_;  // 0: a stream that does not drive (Watch)
  const std::shared_ptr<StreamStart> start_ = std::make_shared<StreamStart>();
  std::shared_ptr<void> stream_slot_;  // of the session owner's stream quota
  std::shared_ptr<FrameStream<Reactor>> stream_;
  std::shared_ptr<Session> session_;
};

class DriveReactor final : public FrameStreamReactor<DriveReactor, grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>> {
 public:
  DriveReactor(FiligreeService& service, grpc::CallbackServerContext* context)
      : FrameStreamReactor(service, service.next_driver_id(), this), context_(context) {
    // A driver that half-closes still gets the frame of its last pose: the
    // stream finishes once a frame includes it. The observer lives in the
    // stream (so `stream` is alive whenever it runs) and may outlive this.
    stream_->on_event([state = ending_, stream = stream_.get(), driver = driver_](const PublishedFrame* frame) {
      std::lock_guard lock(state->mutex);
      if (!frame) return;  // the session closed: the stream is finished already
      if (const auto it = frame->pose_of_driver.find(driver); it != frame->pose_of_driver.end())
        state->answered = std::max(state->answered, it->second);
      if (state->half_closed && state->answered >= state->submitted) stream->writer().finish(grpc::Status::OK, /*flush=*/true);
    });
    StartRead(&request_bytes_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client is done driving: finish after the frame of its last pose
      stream_slot_.reset();  // a half-closed stream no longer counts (before the client can see the end)
      std::lock_guard lock(ending_->mutex);
      ending_->half_closed = true;
      if (!session_ || ending_->answered >= ending_->submitted) stream_->writer().finish(grpc::Status::OK, /*flush=*/true);
      return;
    }
    if (const grpc::Status parsed = parse_request(request_bytes_, request_); !parsed.ok()) return stream_->writer().finish(parsed);
    // The first request names the session: no read until it is there.
    if (!session_) return open(*context_, request_.session_id(), Role::kEditor);
    take_request();
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<DriveReactor>>& stream) override {
    if (status.ok()) {
      stream_->set_format(request_.frame_format());
      session_->subscribe(stream_, session_->version());
      take_request();  // may end the stream: `this` is not touched after it
    }
    end_start(started, stream, status);
  }

  // Submits the request just read and reads the next.
  void take_request() {
    try {
      submit_pose(*session_, driver_, request_);
      const bool pose = !request_.positions().empty() || request_.has_joints();  // not a keyframe request alone
      std::lock_guard lock(ending_->mutex);
      if (pose) ending_->submitted = std::max(ending_->submitted, request_.pose_id());
    } catch (const PoseError& e) {
      // That pose is refused, not the stream: the client hears which and
      // why, the session is unchanged, and the next good pose is answered.
      refuse(request_.pose_id(), e.what());
    } catch (const StoreUnavailable& e) {  // not journaled, so not acknowledged: the client resends
      return stream_->writer().finish({grpc::StatusCode::UNAVAILABLE, e.what()});
    }
    StartRead(&request_bytes_);
  }

  // A message answering pose `pose_id` as refused (Frame.refused), queued
  // like a keyframe: it is never dropped for a newer frame.
  void refuse(std::uint64_t pose_id, const std::string& why) {
    v1::Frame answer;
    answer.set_pose_id(pose_id);
    answer.mutable_refused()->set_code(static_cast<std::uint32_t>(grpc::StatusCode::INVALID_ARGUMENT));
    answer.mutable_refused()->set_message(why);
    auto out = std::make_shared<OutgoingFrame>();
    grpc::Slice bytes(answer.SerializeAsString());
    out->bytes = grpc::ByteBuffer(&bytes, 1);
    stream_->writer().send(std::move(out), /*droppable=*/false);
  }

  // The newest pose id submitted and the newest a frame has answered.
  struct Ending {
    std::mutex mutex;
    std::uint64_t submitted = 0, answered = 0;
    bool half_closed = false;
  };

  grpc::CallbackServerContext* context_;
  std::shared_ptr<Ending> ending_ = std::make_shared<Ending>();
  grpc::ByteBuffer request_bytes_;
  v1::DriveRequest request_;
};

// A watching stream's start (Watch, Follow) once its session is admitted:
// subscribes it as `request` says and ends the start.
template <class Reactor>
void start_watching(FiligreeService& service, const grpc::Status& status, const std::shared_ptr<Session>& session,
                    const v1::WatchRequest& request, const std::shared_ptr<StreamStart>& started,
                    const std::shared_ptr<FrameStream<Reactor>>& stream) {
  if (!status.ok()) return end_start(started, stream, status);
  stream->set_format(request.frame_format());
  // 0: the client has seen nothing yet and gets the current frame, even the rest frame.
  const std::optional<std::uint64_t> after =
      request.after_version() == 0 ? std::nullopt : std::optional<std::uint64_t>(request.after_version());
  if (session->needs_single(request.frame_format())) {
    // subscribe() transcodes the current frame into one buffer first: on a
    // job thread, not one of the callback threads. The start holds the
    // reactor until it ends.
    return service.run_job(
        [session, stream, started, after] {
          session->subscribe(stream, after);
          end_start(started, stream, grpc::Status::OK);
        },
        [started, stream](const grpc::Status& why) { end_start(started, stream, why); });
  }
  session->subscribe(stream, after);
  end_start(started, stream, grpc::Status::OK);
}

class WatchReactor final : public FrameStreamReactor<WatchReactor, grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  WatchReactor(FiligreeService& service, grpc::CallbackServerContext* context, const grpc::ByteBuffer& request_bytes)
      : FrameStreamReactor(service, 0, this) {
    if (const grpc::Status parsed = parse_request(request_bytes, request_); !parsed.ok()) {
      stream_->writer().finish(parsed);
    } else {
      open(*context, request_.session_id(), Role::kViewer);
    }
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<WatchReactor>>& stream) override {
    start_watching(service_, status, session_, request_, started, stream);
  }

  v1::WatchRequest request_;
};

// Watch with acknowledgements: the stream's writer keeps at most
// max_in_flight frames unacknowledged (StreamWriter::set_window), so what
// waits in the HTTP/2 window is bounded in frames, not only in bytes.
class FollowReactor final : public FrameStreamReactor<FollowReactor, grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>> {
 public:
  static constexpr std::uint32_t kDefaultInFlight = 2, kMostInFlight = 8;

  FollowReactor(FiligreeService& service, grpc::CallbackServerContext* context)
      : FrameStreamReactor(service, 0, this), context_(context) {
    StartRead(&request_bytes_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) return stream_->writer().finish(grpc::Status::OK);  // the client is done reading
    if (const grpc::Status parsed = parse_request(request_bytes_, request_); !parsed.ok())
      return stream_->writer().finish(parsed);
    if (!watch_) {
      // The first message says what to follow: no read until the session is there.
      if (request_.max_in_flight() > kMostInFlight)
        return stream_->writer().finish({grpc::StatusCode::INVALID_ARGUMENT,
                                         "max_in_flight is at most " + std::to_string(kMostInFlight) + ", not " +
                                             std::to_string(request_.max_in_flight())});
      stream_->acknowledged_within(request_.max_in_flight() == 0 ? kDefaultInFlight : request_.max_in_flight());
      watch_ = request_.watch();
      return open(*context_, watch_->session_id(), Role::kViewer);
    }
    stream_->acknowledge(request_.read_version());
    StartRead(&request_bytes_);
  }

 private:
  void start(const grpc::Status& status, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<FollowReactor>>& stream) override {
    if (status.ok()) StartRead(&request_bytes_);  // acknowledgements from now on
    start_watching(service_, status, session_, *watch_, started, stream);
  }

  grpc::CallbackServerContext* context_;
  grpc::ByteBuffer request_bytes_;
  v1::FollowRequest request_;
  std::optional<v1::WatchRequest> watch_;
};

// Plays a clip of the session's rig: a thread samples it at the stream's
// clock and submits each sample as a skeletal pose of this stream, waiting
// for the frame that includes one before sampling the next (so a slow
// session lowers the sample rate instead of queueing poses).
class PlayClipReactor final : public FrameStreamReactor<PlayClipReactor, grpc::ServerWriteReactor<grpc::ByteBuffer>> {
 public:
  PlayClipReactor(FiligreeService& service, grpc::CallbackServerContext* context, const grpc::ByteBuffer& request_bytes)
      : FrameStreamReactor(service, service.next_driver_id(), this) {
    if (const grpc::Status parsed = parse_request(request_bytes, request_); !parsed.ok()) {
      stream_->writer().finish(parsed);
    } else {
      open(*context, request_.session_id(), Role::kEditor);
    }
  }
  void OnCancel() override {
    state_->end();
    FrameStreamReactor::OnCancel();
  }
  void OnDone() override {
    state_->end();
    if (player_.joinable()) player_.get_id() == std::this_thread::get_id() ? player_.detach() : player_.join();
    FrameStreamReactor::OnDone();  // deletes this
  }

 private:
  void start(const grpc::Status& admitted, const std::shared_ptr<StreamStart>& started,
             const std::shared_ptr<FrameStream<PlayClipReactor>>& stream) override {
    grpc::Status status = admitted.ok() ? check() : admitted;
    if (status.ok() && !service_.begin_job()) status = {grpc::StatusCode::UNAVAILABLE, "the server is shutting down"};
    if (!status.ok()) {
      session_.reset();
      return end_start(started, stream, status);
    }
    stream_->set_format(request_.frame_format());
    stream_->set_clip_times(clip_times_);
    // The session may offer after this reactor is gone: the observer owns what it touches.
    stream_->on_event([state = state_, driver = driver_](const PublishedFrame* frame) {
      std::lock_guard lock(state->mutex);
      if (!frame) {
        state->ended = true;  // the session closed or left: the stream is finished already
      } else if (const auto it = frame->pose_of_driver.find(driver); it != frame->pose_of_driver.end()) {
        state->shown = std::max(state->shown, it->second);
      }
      state->changed.notify_all();
    });
    session_->subscribe(stream_, session_->version());
    try {
      player_ = std::thread([this] {
        {  // not before player_ is set: the stream may end with it, and OnDone joins player_
          std::unique_lock lock(state_->mutex);
          state_->changed.wait(lock, [&] { return state_->playing; });
        }
        const grpc::Status status = play();
        service_.end_job();
        stream_->writer().finish(status, /*flush=*/true);
      });
      std::lock_guard lock(state_->mutex);
      state_->playing = true;
      state_->changed.notify_all();
    } catch (const std::system_error& e) {
      service_.end_job();
      status = {grpc::StatusCode::RESOURCE_EXHAUSTED, std::string("the server could not start a thread: ") + e.what()};
    }
    end_start(started, stream, status);
  }

  static constexpr double kMostSamplesPerSecond = 60.0;

  grpc::Status check() {
    if (!session_->has_skeleton())
      return {grpc::StatusCode::FAILED_PRECONDITION, "session " + session_->id() + " has no skeleton (its upload was not a skinned glTF)"};
    clip_ = session_->clip(request_.clip());
    if (!clip_) return {grpc::StatusCode::NOT_FOUND, "session " + session_->id() + " has no clip '" + request_.clip() + "'"};
    if (!std::isfinite(request_.speed()) || request_.speed() < 0.0 || !std::isfinite(request_.start_seconds()) ||
        !std::isfinite(request_.max_rate()) || request_.max_rate() < 0.0)
      return {grpc::StatusCode::INVALID_ARGUMENT, "speed, start_seconds and max_rate must be finite, speed and max_rate ≥ 0"};
    return grpc::Status::OK;
  }

  grpc::Status play() {
    using Clock = std::chrono::steady_clock;
    const double duration = clip_->duration();
    const double speed = request_.speed() > 0.0 ? request_.speed() : 1.0;
    const double rate = request_.max_rate() > 0.0 ? std::min(request_.max_rate(), kMostSamplesPerSecond) : kMostSamplesPerSecond;
    const auto interval = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate));
    const auto start = Clock::now();
    const std::string name = request_.client_name().empty() ? "clip " + request_.clip() : request_.client_name();
    for (std::uint64_t id = 1;; ++id) {
      const auto tick = Clock::now();
      double t = request_.start_seconds() + speed * std::chrono::duration<double>(tick - start).count();
      const bool last = !request_.loop() && t >= duration;
      if (last) t = duration;
      if (request_.loop() && duration > 0.0) t = std::fmod(t, duration);
      clip_times_->record(id, t);  // before the frame that shows it can be offered
      try {
        session_->submit_clip_sample({driver_, name, id}, *clip_, t);
      } catch (const PoseError& e) {
        return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
      } catch (const StoreUnavailable& e) {
        return {grpc::StatusCode::UNAVAILABLE, e.what()};
      }
      PlayState& s = *state_;
      std::unique_lock lock(s.mutex);
      // The next sample once this one is shown, and not before the rate allows.
      s.changed.wait(lock, [&] { return s.ended || s.shown >= id; });
      if (s.ended) return grpc::Status::CANCELLED;
      if (last) return grpc::Status::OK;
      s.changed.wait_until(lock, tick + interval, [&] { return s.ended; });
      if (s.ended) return grpc::Status::CANCELLED;
    }
  }

  v1::PlayClipRequest request_;  // set once, in the constructor
  const AnimationClip* clip_ = nullptr;  // owned by the session's rig
  struct PlayState {
    std::mutex mutex;
    std::condition_variable changed;
    bool ended = false;       // cancelled, done, or the session's streams closed
    bool playing = false;     // player_ is set
    std::uint64_t shown = 0;  // the newest sample a frame includes
    void end() {
      std::lock_guard lock(mutex);
      ended = true;
      changed.notify_all();
    }
  };
  const std::shared_ptr<PlayState> state_ = std::make_shared<PlayState>();
  const std::shared_ptr<ClipTimes> clip_times_ = std::make_shared<ClipTimes>();
  std::thread player_;
};

}  // namespace

grpc::ServerWriteReactor<grpc::ByteBuffer>* FiligreeService::PlayClip(grpc::CallbackServerContext* context,
                                                                      const grpc::ByteBuffer* request) {
  return new PlayClipReactor(*this, context, *request);
}

grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse>* FiligreeService::CreateSession(
    grpc::CallbackServerContext* context) {
  return new CreateReactor(*this, context);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FiligreeService::Drive(grpc::CallbackServerContext* context) {
  return new DriveReactor(*this, context);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* FiligreeService::Watch(grpc::CallbackServerContext* context,
                                                                   const grpc::ByteBuffer* request) {
  return new WatchReactor(*this, context, *request);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FiligreeService::Follow(grpc::CallbackServerContext* context) {
  return new FollowReactor(*this, context);
}

// ------------------------------------------------------------ unary calls

grpc::ServerUnaryReactor* FiligreeService::JoinSession(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                                       grpc::ByteBuffer* response) {
  v1::JoinSessionRequest r;
  if (const grpc::Status parsed = parse_request(*request, r); !parsed.ok()) return finish_unary(context, parsed);
  return unary_on_session(context, r.session_id(), Role::kViewer, [context, response](Session& s) {
    // The mesh's bytes, shared by every join, and then the caller's role:
    // one more field, which protobuf merges into the same SessionInfo.
    v1::SessionInfo role;
    role.set_role(s.authorize(metadata(*context, "x-filigree-token")) == Role::kEditor ? v1::ROLE_EDITOR : v1::ROLE_VIEWER);
    std::vector<grpc::Slice> slices;
    (void)s.info_wire().Dump(&slices);
    slices.emplace_back(role.SerializeAsString());
    *response = grpc::ByteBuffer(slices.data(), slices.size());
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::SubmitPose(grpc::CallbackServerContext* context,
                                                      const v1::DriveRequest* request, v1::SubmitPoseResponse* response) {
  return unary_on_session(context, request->session_id(), Role::kEditor, [request, response](Session& s) -> grpc::Status {
    try {
      response->set_accepted_at_version(s.accepted_version());
      submit_pose(s, /*driver=*/0, *request);
    } catch (const PoseError& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const StoreUnavailable& e) {
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    }
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::SetHandles(grpc::CallbackServerContext* context,
                                                      const v1::SetHandlesRequest* request, v1::SetHandlesResponse* response) {
  return unary_on_session(context, request->session_id(), Role::kEditor, [request, response](Session& s) -> grpc::Status {
    std::vector<std::pair<Index, Vec3>> handles;
    for (const v1::Handle& h : request->handles()) handles.emplace_back(h.vertex(), Vec3(h.x(), h.y(), h.z()));
    try {
      response->set_accepted_at_version(s.accepted_version());
      response->set_handles_in_session(static_cast<std::uint32_t>(s.set_handles(request->client_name(), handles)));
    } catch (const PoseError& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const StoreUnavailable& e) {  // handles are journaled now
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    }
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::GetHandles(grpc::CallbackServerContext* context,
                                                      const v1::GetHandlesRequest* request, v1::SessionHandles* response) {
  return unary_on_session(context, request->session_id(), Role::kViewer, [response](Session& s) {
    *response = s.handles();
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::GetOverlays(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                                       grpc::ByteBuffer* response) {
  v1::GetOverlaysRequest r;
  if (const grpc::Status parsed = parse_request(*request, r); !parsed.ok()) return finish_unary(context, parsed);
  return unary_on_session(context, r.session_id(), Role::kViewer, [response](Session& s) {
    *response = s.overlays_wire();
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::GetState(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                                    grpc::ByteBuffer* response) {
  v1::GetStateRequest r;
  if (const grpc::Status parsed = parse_request(*request, r); !parsed.ok()) return finish_unary(context, parsed);
  const v1::FrameFormat format = r.frame_format();
  return unary_on_session(
      context, r.session_id(), Role::kViewer,
      [response, format](Session& s) -> grpc::Status {
        try {
          *response = s.state_wire(format);
        } catch (const std::exception& e) {
          return {grpc::StatusCode::UNAVAILABLE, e.what()};
        }
        return grpc::Status::OK;
      },
      // Transcoding the frame into one buffer: a job.
      [format](const Session& s) { return s.needs_single(format); });
}

namespace {

grpc::Status apply_options(Session& s, double threshold, bool whole_mesh, grpc::ByteBuffer* response) {
  try {
    const std::uint64_t accepted = s.set_threshold(threshold, whole_mesh);
    // Not the current frame's version: a frame may have been published since
    // the change, and a client waiting for a frame after it would wait forever.
    *response = s.info_wire(accepted);
  } catch (const StoreUnavailable& e) {
    return {grpc::StatusCode::UNAVAILABLE, e.what()};
  } catch (const HierarchyError& e) {
    return {grpc::StatusCode::FAILED_PRECONDITION, std::string("this session's hierarchy cannot run a finite T: ") + e.what()};
  } catch (const std::bad_alloc&) {
    return {grpc::StatusCode::RESOURCE_EXHAUSTED, "out of memory while preparing the threshold"};
  } catch (const std::exception& e) {
    // Off a gRPC thread an escaped exception would end the process.
    return {grpc::StatusCode::INTERNAL, std::string("setting the options failed: ") + e.what()};
  }
  return grpc::Status::OK;
}

}  // namespace

grpc::ServerUnaryReactor* FiligreeService::SetOptions(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request_bytes,
                                                      grpc::ByteBuffer* response) {
  v1::SetOptionsRequest r;
  if (const grpc::Status parsed = parse_request(*request_bytes, r); !parsed.ok()) return finish_unary(context, parsed);
  const double threshold = r.threshold();
  const bool whole_mesh = r.whole_mesh();
  const bool valid = threshold >= 0.0 && !std::isinf(threshold);
  return unary_on_session(
      context, r.session_id(), Role::kEditor,
      [threshold, whole_mesh, valid, response](Session& s) -> grpc::Status {
        if (!valid) return {grpc::StatusCode::INVALID_ARGUMENT, "threshold must be a finite number ≥ 0 (whole_mesh for ∞)"};
        return apply_options(s, threshold, whole_mesh, response);
      },
      // The first finite T of a mesh derives its node graph and region
      // optimisation's data (~1 s at 1.25M vertices), and whole-mesh
      // optimisation factorises the mesh (seconds): a job.
      [threshold, whole_mesh, valid](const Session& s) { return valid && s.threshold_needs_preparation(threshold, whole_mesh); });
}

grpc::ServerUnaryReactor* FiligreeService::CloseSession(grpc::CallbackServerContext* context,
                                                        const v1::CloseSessionRequest* request, v1::CloseSessionResponse*) {
  return unary_on_session(context, request->session_id(), Role::kEditor, [this](Session& s) -> grpc::Status {
    try {
      registry_.close(s.id());
    } catch (const StoreUnavailable& e) {
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    }
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::LocateSession(grpc::CallbackServerContext* context,
                                                         const v1::LocateSessionRequest* request,
                                                         v1::SessionLocation* response) {
  // Where a session lives is told only to whoever reaches it: a token of
  // the session, or the API key that owns it. Anyone else hears what an
  // unknown id hears.
  const std::string& id = request->session_id();
  std::string owner;
  if (const std::shared_ptr<const ApiKeys> keys = api_keys())
    if (const ApiKey* key = keys->find(metadata(*context, "x-filigree-api-key"))) owner = key->name;
  grpc::Status status;
  try {
    const SessionLocation where = registry_.reachable(id, metadata(*context, "x-filigree-token"), owner)
                                      ? registry_.locate(id)
                                      : SessionLocation{};
    if (!where.exists) {
      status = no_such_session(id);
    } else {
      response->set_session_id(id);
      response->set_replica_id(where.replica_id);
      response->set_address(where.address);
      response->set_here(where.here);
    }
  } catch (const StoreUnavailable& e) {
    status = {grpc::StatusCode::UNAVAILABLE, e.what()};
  }
  return finish_unary(context, status);
}

grpc::ServerUnaryReactor* FiligreeService::ListSessions(grpc::CallbackServerContext* context,
                                                        const v1::ListSessionsRequest*, v1::ListSessionsResponse* response) {
  std::shared_ptr<const ApiKeys> keys;
  const ApiKey* key = nullptr;
  if (const grpc::Status status = check_api_key(*context, &keys, &key); !status.ok()) return finish_unary(context, status);
  for (const auto& s : registry_.loaded()) {
    if (key && s->owner() != key->name) continue;  // a key lists its own sessions only
    s->describe(*response->add_sessions());
  }
  return finish_unary(context, grpc::Status::OK);
}

}  // namespace filigree::server
