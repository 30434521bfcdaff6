#include "server/filigree_service.h"

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <string>
#include <system_error>
#include <thread>
#include <utility>

#include <spdlog/spdlog.h>

#include "server/call_arguments.h"
#include "server/create_reactor.h"
#include "server/drive_reactor.h"
#include "server/play_clip_reactor.h"
#include "server/pose_request.h"
#include "server/resident_memory.h"
#include "server/export_history_reactor.h"
#include "server/presence_reactor.h"
#include "server/rest_mesh_reactor.h"
#include "server/watch_reactors.h"

namespace filigree::server {
namespace {

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

std::shared_ptr<void> FiligreeService::take_export_slot() {
  return exports_.take("exports", std::max(1u, std::thread::hardware_concurrency()));
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

void FiligreeService::watch_preprocessing(std::atomic<bool>* stop) {
  std::lock_guard lock(stops_mutex_);
  stops_.insert(stop);
  if (stop_preprocessing_) *stop = true;
}

void FiligreeService::unwatch_preprocessing(std::atomic<bool>* stop) {
  std::lock_guard lock(stops_mutex_);
  stops_.erase(stop);
}

void FiligreeService::drain() {
  // Preprocessing in progress stops at its next check: a pathological mesh
  // cannot hold a shutdown (its upload, not yet a session, is refused).
  {
    std::lock_guard lock(stops_mutex_);
    stop_preprocessing_ = true;
    for (std::atomic<bool>* stop : stops_) *stop = true;
  }
  std::unique_lock lock(jobs_mutex_);
  draining_ = true;
  jobs_done_.wait(lock, [&] { return jobs_ == 0; });
}

// ------------------------------------------------------------ streams

grpc::ServerWriteReactor<grpc::ByteBuffer>* FiligreeService::PlayClip(grpc::CallbackServerContext* context,
                                                                      const grpc::ByteBuffer* request) {
  return new_play_clip_reactor(*this, context, *request);
}

grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse>* FiligreeService::CreateSession(
    grpc::CallbackServerContext* context) {
  return new_create_reactor(*this, context);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FiligreeService::Drive(grpc::CallbackServerContext* context) {
  return new_drive_reactor(*this, context);
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* FiligreeService::Watch(grpc::CallbackServerContext* context,
                                                                   const grpc::ByteBuffer* request) {
  return new_watch_reactor(*this, context, *request);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* FiligreeService::Follow(grpc::CallbackServerContext* context) {
  return new_follow_reactor(*this, context);
}

// ------------------------------------------------------------ unary calls

grpc::ServerUnaryReactor* FiligreeService::JoinSession(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                                       grpc::ByteBuffer* response) {
  v1::JoinSessionRequest r;
  if (const grpc::Status parsed = parse_request(*request, r); !parsed.ok()) return finish_unary(context, parsed);
  return unary_on_session(context, r.session_id(), Role::kViewer, [this, context, response](Session& s) {
    // The mesh's bytes, shared by every join, and then the caller's role:
    // one more field, which protobuf merges into the same SessionInfo.
    v1::SessionInfo role;
    role.set_role(s.authorize(metadata(*context, "x-filigree-token")) == Role::kEditor ? v1::ROLE_EDITOR : v1::ROLE_VIEWER);
    std::vector<grpc::Slice> slices;
    (void)s.info_wire(limits_.inline_rest_bytes()).Dump(&slices);
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
      response->set_handles_in_session(static_cast<std::uint32_t>(s.set_handles(request->client_name(), handles, request->gesture_id())));
    } catch (const PoseError& e) {
      return {grpc::StatusCode::INVALID_ARGUMENT, e.what()};
    } catch (const StoreUnavailable& e) {  // handles are journaled now
      return {grpc::StatusCode::UNAVAILABLE, e.what()};
    }
    return grpc::Status::OK;
  });
}

grpc::ServerWriteReactor<v1::RestMeshPart>* FiligreeService::GetRestMesh(grpc::CallbackServerContext* context,
                                                                         const v1::GetRestMeshRequest* request) {
  return new_rest_mesh_reactor(*this, context, *request);
}

grpc::ServerWriteReactor<v1::Presence>* FiligreeService::WatchPresence(grpc::CallbackServerContext* context,
                                                                       const v1::WatchPresenceRequest* request) {
  return new_presence_reactor(*this, context, *request);
}

grpc::ServerWriteReactor<v1::HistoryFrame>* FiligreeService::ExportHistory(grpc::CallbackServerContext* context,
                                                                           const v1::ExportHistoryRequest* request) {
  return new_export_history_reactor(*this, context, *request);
}

grpc::ServerUnaryReactor* FiligreeService::GetHandles(grpc::CallbackServerContext* context,
                                                      const v1::GetHandlesRequest* request, v1::SessionHandles* response) {
  return unary_on_session(context, request->session_id(), Role::kViewer, [response](Session& s) {
    *response = s.handles();
    return grpc::Status::OK;
  });
}

grpc::ServerUnaryReactor* FiligreeService::SetDetail(grpc::CallbackServerContext* context,
                                                     const v1::SetDetailRequest* request, v1::SetDetailResponse* response) {
  if (request->max_vertices() == 0)
    return finish_unary(context, {grpc::StatusCode::INVALID_ARGUMENT, "max_vertices must be at least 1"});
  const std::uint64_t stream_id = request->stream_id();
  const std::uint32_t max_vertices = request->max_vertices();
  return unary_on_session(context, request->session_id(), Role::kViewer, [=](Session& s) {
    const std::optional<std::uint32_t> level = stream_id == 0 ? std::nullopt : s.set_detail(stream_id, max_vertices);
    if (!level)
      return grpc::Status(grpc::StatusCode::NOT_FOUND,
                          "no stream " + std::to_string(stream_id) + " at a level of detail in this session");
    response->set_vertex_count(*level);
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

grpc::Status apply_options(Session& s, double threshold, bool whole_mesh, const std::string& author, std::size_t inline_rest,
                           grpc::ByteBuffer* response) {
  try {
    const std::uint64_t accepted = s.set_threshold(threshold, whole_mesh, &author);
    // Not the current frame's version: a frame may have been published since
    // the change, and a client waiting for a frame after it would wait forever.
    *response = s.info_wire(inline_rest, accepted);
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
  const std::size_t inline_rest = limits_.inline_rest_bytes();
  return unary_on_session(
      context, r.session_id(), Role::kEditor,
      [threshold, whole_mesh, valid, inline_rest, response, author = r.client_name()](Session& s) -> grpc::Status {
        if (!valid) return {grpc::StatusCode::INVALID_ARGUMENT, "threshold must be a finite number ≥ 0 (whole_mesh for ∞)"};
        return apply_options(s, threshold, whole_mesh, author, inline_rest, response);
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
