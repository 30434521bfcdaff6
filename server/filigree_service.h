#pragma once
// The filigree.v1.Filigree service on gRPC's callback API: every RPC is a
// reactor; nothing blocks a gRPC thread (preprocessing runs on its own thread).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <string>

#include "filigree/v1/filigree.grpc.pb.h"
#include "server/api_key_ledger.h"
#include "server/api_keys.h"
#include "server/hierarchy_cache.h"
#include "server/session_registry.h"
#include "server/slot_counter.h"
#include "server/turns.h"

namespace filigree::server {

struct ServiceLimits {
  std::uint64_t max_mesh_bytes = 256ull << 20;
  std::uint64_t max_vertices = 5'000'000;
  std::uint64_t max_streams_per_session = 256;  // Drive, Watch and PlayClip streams of one session (0: no limit)
  // Resident memory beyond which uploads are refused once idle sessions are evicted (0: no limit).
  std::uint64_t max_memory_bytes = 0;
  // Uploads preprocessed at once (more wait their turn), at a lower CPU
  // priority than the sessions' frames.
  unsigned preprocessing_slots = 1;
  // Sessions loaded from the store at once (their records, hierarchies and
  // models; 0: one per core); more wait their turn on their own threads.
  unsigned session_loads = 0;
  // Longest an upload may take to send its bytes (slow or stalled clients
  // hold memory and a stream); 0: no limit.
  double upload_seconds = 300.0;
  // Largest gRPC message the server sends (--max-message-mib). A rest mesh
  // over half of it leaves SessionInfo for GetRestMesh (RestMesh.in_parts).
  std::uint64_t max_message_bytes = 64ull << 20;
  std::size_t inline_rest_bytes() const { return static_cast<std::size_t>(max_message_bytes / 2); }
};

// Every method on the callback API (v1::Filigree::CallbackService, spelled
// out: a method left out here would be a synchronous one). The frame streams
// (Drive, Watch, Follow, PlayClip) are raw methods: each frame is serialized once
// and its bytes written by every stream (serialized_frame.h); so are the
// answers with a SessionInfo (JoinSession, SetOptions), whose meshes are
// serialized once per mesh (session_info_wire.h), GetState's, which shares
// the frames' bytes, and GetOverlays', serialized once per frame.
using rpc = v1::Filigree;
using FiligreeServiceBase = rpc::WithCallbackMethod_CreateSession<rpc::WithRawCallbackMethod_JoinSession<
    rpc::WithRawCallbackMethod_Drive<rpc::WithCallbackMethod_SubmitPose<rpc::WithCallbackMethod_SetHandles<
        rpc::WithRawCallbackMethod_GetOverlays<rpc::WithRawCallbackMethod_Watch<rpc::WithRawCallbackMethod_GetState<
            rpc::WithRawCallbackMethod_SetOptions<rpc::WithCallbackMethod_CloseSession<rpc::WithCallbackMethod_ListSessions<
                rpc::WithCallbackMethod_LocateSession<rpc::WithRawCallbackMethod_PlayClip<
                    rpc::WithRawCallbackMethod_Follow<rpc::WithCallbackMethod_GetHandles<rpc::WithCallbackMethod_GetRestMesh<rpc::WithCallbackMethod_SetDetail<
                        rpc::WithCallbackMethod_GetHistory<rpc::WithCallbackMethod_Undo<rpc::WithCallbackMethod_Redo<
                            rpc::WithCallbackMethod_CreateCheckpoint<rpc::WithCallbackMethod_RestoreCheckpoint<
                                rpc::WithCallbackMethod_DiffCheckpoint<rpc::WithCallbackMethod_WatchPresence<
                                    rpc::WithCallbackMethod_SetPresence<rpc::WithCallbackMethod_ExportHistory<
                                        rpc::Service>>>>>>>>>>>>>>>>>>>>>>>>>>;

class FiligreeService final : public FiligreeServiceBase {
 public:
  FiligreeService(SessionRegistry& registry, HierarchyCache& cache, ServiceLimits limits);
  ~FiligreeService() override;

  // Refuses new background work (uploads, session loads) and waits for what runs to finish.
  void drain();

  grpc::ServerBidiReactor<v1::CreateSessionRequest, v1::CreateSessionResponse>* CreateSession(
      grpc::CallbackServerContext* context) override;
  // Request: a JoinSessionRequest; answer: a SessionInfo whose meshes are
  // serialized once per mesh (session_info_wire.h).
  grpc::ServerUnaryReactor* JoinSession(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                        grpc::ByteBuffer* response) override;
  // Requests: a DriveRequest per message; frames out.
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Drive(grpc::CallbackServerContext* context) override;
  // Request: a PlayClipRequest; frames out.
  grpc::ServerWriteReactor<grpc::ByteBuffer>* PlayClip(grpc::CallbackServerContext* context,
                                                       const grpc::ByteBuffer* request) override;
  grpc::ServerUnaryReactor* SubmitPose(grpc::CallbackServerContext* context, const v1::DriveRequest* request,
                                       v1::SubmitPoseResponse* response) override;
  grpc::ServerUnaryReactor* SetHandles(grpc::CallbackServerContext* context, const v1::SetHandlesRequest* request,
                                       v1::SetHandlesResponse* response) override;
  // A session's rest mesh in parts (rest_mesh_reactor.h).
  grpc::ServerWriteReactor<v1::RestMeshPart>* GetRestMesh(grpc::CallbackServerContext* context,
                                                          const v1::GetRestMeshRequest* request) override;
  grpc::ServerUnaryReactor* GetHandles(grpc::CallbackServerContext* context, const v1::GetHandlesRequest* request,
                                       v1::SessionHandles* response) override;
  grpc::ServerUnaryReactor* SetDetail(grpc::CallbackServerContext* context, const v1::SetDetailRequest* request,
                                      v1::SetDetailResponse* response) override;
  // The edit history, checkpoints and presence (history_calls.cpp).
  grpc::ServerUnaryReactor* GetHistory(grpc::CallbackServerContext* context, const v1::GetHistoryRequest* request,
                                       v1::History* response) override;
  grpc::ServerUnaryReactor* Undo(grpc::CallbackServerContext* context, const v1::UndoRequest* request,
                                 v1::UndoResponse* response) override;
  grpc::ServerUnaryReactor* Redo(grpc::CallbackServerContext* context, const v1::UndoRequest* request,
                                 v1::UndoResponse* response) override;
  grpc::ServerUnaryReactor* CreateCheckpoint(grpc::CallbackServerContext* context, const v1::CreateCheckpointRequest* request,
                                             v1::Checkpoint* response) override;
  grpc::ServerUnaryReactor* RestoreCheckpoint(grpc::CallbackServerContext* context,
                                              const v1::RestoreCheckpointRequest* request, v1::UndoResponse* response) override;
  grpc::ServerUnaryReactor* DiffCheckpoint(grpc::CallbackServerContext* context, const v1::DiffCheckpointRequest* request,
                                           v1::CheckpointDiff* response) override;
  grpc::ServerUnaryReactor* SetPresence(grpc::CallbackServerContext* context, const v1::SetPresenceRequest* request,
                                        v1::SetPresenceResponse* response) override;
  grpc::ServerWriteReactor<v1::Presence>* WatchPresence(grpc::CallbackServerContext* context,
                                                        const v1::WatchPresenceRequest* request) override;
  grpc::ServerWriteReactor<v1::HistoryFrame>* ExportHistory(grpc::CallbackServerContext* context,
                                                            const v1::ExportHistoryRequest* request) override;
  // Request: a GetOverlaysRequest; answer: an Overlays serialized once per frame.
  grpc::ServerUnaryReactor* GetOverlays(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                        grpc::ByteBuffer* response) override;
  // Request: a WatchRequest; frames out.
  grpc::ServerWriteReactor<grpc::ByteBuffer>* Watch(grpc::CallbackServerContext* context,
                                                    const grpc::ByteBuffer* request) override;
  // Requests: FollowRequests (what to watch, then acknowledgements); frames out.
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Follow(grpc::CallbackServerContext* context) override;
  // Request: a GetStateRequest; answer: a SessionState whose frames are the
  // bytes the streams send (serialized_frame.h).
  grpc::ServerUnaryReactor* GetState(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                     grpc::ByteBuffer* response) override;
  // Request: a SetOptionsRequest; answer: a SessionInfo, as JoinSession's.
  grpc::ServerUnaryReactor* SetOptions(grpc::CallbackServerContext* context, const grpc::ByteBuffer* request,
                                       grpc::ByteBuffer* response) override;
  grpc::ServerUnaryReactor* CloseSession(grpc::CallbackServerContext* context, const v1::CloseSessionRequest* request,
                                         v1::CloseSessionResponse* response) override;
  grpc::ServerUnaryReactor* LocateSession(grpc::CallbackServerContext* context, const v1::LocateSessionRequest* request,
                                         v1::SessionLocation* response) override;
  grpc::ServerUnaryReactor* ListSessions(grpc::CallbackServerContext* context, const v1::ListSessionsRequest* request,
                                         v1::ListSessionsResponse* response) override;

  SessionRegistry& registry() { return registry_; }
  HierarchyCache& cache() { return cache_; }
  const ServiceLimits& limits() const { return limits_; }
  // Work off gRPC's threads (uploads, session loads, a first finite T,
  // clips): counted so drain() can wait for it.
  bool begin_job();
  void end_job();
  // Runs `work` as a job on a thread of its own; when the server is shutting
  // down (UNAVAILABLE) or no thread can start (RESOURCE_EXHAUSTED), calls
  // `refused` with why instead, on the caller's thread.
  void run_job(std::function<void()> work, const std::function<void(const grpc::Status&)>& refused);
  // Preprocessing turns (limits().preprocessing_slots at once): held while
  // an upload is parsed and preprocessed.
  void acquire_preprocessing();
  void release_preprocessing();
  // Reserves `bytes` of an upload (its declared size) against
  // limits().max_memory_bytes, with what the server holds now and what other
  // uploads in progress reserved, under one lock: concurrent uploads cannot
  // all pass one check. *reserved holds them until it is released (the
  // upload became a session or failed). RESOURCE_EXHAUSTED with the figures.
  grpc::Status reserve_upload_memory(std::uint64_t bytes, std::shared_ptr<void>* reserved);
  // An upload's preprocessing stop flag (PreprocessOptions::stop), which
  // its reactor sets when the call is cancelled or its deadline passes:
  // the service sets it too when it starts draining (at once if it has).
  // Unwatched before the flag goes away.
  void watch_preprocessing(std::atomic<bool>* stop);
  void unwatch_preprocessing(std::atomic<bool>* stop);
  // Calls waiting for a turn to load their session (limits().session_loads).
  std::size_t loads_waiting() const;
  // Whether a new upload fits under limits().max_memory_bytes: if the
  // server's resident memory is over it, idle sessions are evicted first;
  // RESOURCE_EXHAUSTED saying the figures if that is not enough.
  grpc::Status admit_memory();
  // Uploads still receiving bytes, tracked so that expire_uploads() can end
  // those past limits().upload_seconds with DEADLINE_EXCEEDED (`expire` does).
  void track_upload(const void* upload, std::function<void()> expire);
  void untrack_upload(const void* upload);
  // Called every second or so (the maintenance loop).
  void expire_uploads();
  std::uint64_t next_driver_id() { return ++driver_ids_; }

  // API keys (--api-keys): null means none are required. Replaced whole on
  // a reload (SIGHUP); calls in flight keep the set they started with.
  void set_api_keys(std::shared_ptr<const ApiKeys> keys);
  std::shared_ptr<const ApiKeys> api_keys() const;
  // The key a CreateSession or ListSessions call presents (x-filigree-api-key).
  // OK with *key null when no keys are configured; else UNAUTHENTICATED
  // (none presented) or PERMISSION_DENIED (not a known key).
  grpc::Status check_api_key(const grpc::CallbackServerContext& context, std::shared_ptr<const ApiKeys>* keys,
                             const ApiKey** key) const;
  // Quotas of `key` at the start of an upload: uploads in the last minute
  // (recorded when admitted) and sessions held, loaded or evicted, with the
  // key's uploads in progress (*pending holds this one's place until it is
  // released). RESOURCE_EXHAUSTED says which.
  grpc::Status admit_upload(const ApiKey& key, std::shared_ptr<void>* pending);
  // Whether `key` may hold `vertices` more (RESOURCE_EXHAUSTED if not),
  // counting its sessions and the vertices other uploads of the key have
  // reserved; if so, *reserved holds these until released (after the
  // session is created, when the registry counts them). Check and
  // reservation are one step: concurrent uploads cannot all pass.
  grpc::Status reserve_vertices(const ApiKey& key, std::uint64_t vertices, std::shared_ptr<void>* reserved);
  // A stream on `session`: refused (RESOURCE_EXHAUSTED) when the session
  // serves limits().max_streams_per_session already or its owner's key has
  // its quota of streams open; else *slot holds the stream's place (and
  // quota) until it is released.
  grpc::Status open_stream(const Session& session, std::shared_ptr<void>* slot);
  // Undo or Redo (history_calls.cpp).
  grpc::ServerUnaryReactor* undo_call(grpc::CallbackServerContext* context, const v1::UndoRequest& request,
                                      v1::UndoResponse* response, bool redo);
  // A place for one ExportHistory call (each deforms a frame per entry on a
  // thread of its own): one per core at once; null when all are taken.
  std::shared_ptr<void> take_export_slot();

  // What a call on a session continues with: the status of authorize() and,
  // when it is OK, the session.
  using SessionContinuation = std::function<void(grpc::Status, std::shared_ptr<Session>)>;
  // Authorizes the call for session `id` (as authorize() below) and runs
  // `then`: at once when the session is in memory; otherwise on a job
  // thread, because loading it (its record, its hierarchy, its model: 1.4 to
  // 2.5 s at 1.25M vertices) would hold one of the few callback threads
  // every call of this server shares. `then` may run before this returns.
  // A server shutting down answers UNAVAILABLE.
  void with_session(grpc::CallbackServerContext& context, const std::string& id, Role needed, SessionContinuation then);
  // A unary call on a session: `body(session)` gives the status to finish
  // with. Where `slow(session)` says so, the body runs as a job (run_job),
  // not on the callback thread every call of this server shares.
  grpc::ServerUnaryReactor* unary_on_session(grpc::CallbackServerContext* context, const std::string& id, Role needed,
                                             std::function<grpc::Status(Session&)> body,
                                             std::function<bool(const Session&)> slow = {});

 private:
  SessionRegistry& registry_;
  HierarchyCache& cache_;
  const ServiceLimits limits_;
  std::atomic<std::uint64_t> driver_ids_{0};
  mutable std::mutex keys_mutex_;
  std::shared_ptr<const ApiKeys> keys_;
  ApiKeyLedger ledger_;
  std::mutex jobs_mutex_;
  std::condition_variable jobs_done_;
  int jobs_ = 0;
  Turns preprocessing_;  // limits_.preprocessing_slots
  Turns loads_;          // limits_.session_loads, or one per core
  bool draining_ = false;
  std::mutex stops_mutex_;
  bool stop_preprocessing_ = false;         // under stops_mutex_: draining
  std::set<std::atomic<bool>*> stops_;     // the watched uploads' stop flags
  std::mutex upload_memory_mutex_;
  std::uint64_t upload_memory_reserved_ = 0;  // declared bytes of uploads in progress
  std::mutex evict_mutex_;     // admit_memory's evictions, one at a time
  SlotCounter uploading_;      // admitted uploads not yet sessions, by API key
  SlotCounter vertices_;       // vertices of those uploads that passed the quota, by API key
  SlotCounter stream_places_;  // streams open, by session id
  SlotCounter exports_;        // ExportHistory calls deforming, server-wide
  struct Upload {
    std::chrono::steady_clock::time_point deadline;
    std::function<void()> expire;
  };
  std::mutex uploads_mutex_;
  std::map<const void*, Upload> uploads_;
};

// Looks up the session and checks the token in the call's metadata
// (x-filigree-token) against `needed`. Returns OK and sets *session, or the
// status to answer with: NOT_FOUND, UNAUTHENTICATED, PERMISSION_DENIED.
// Another replica serving the session, or the shared store unreachable: UNAVAILABLE.
grpc::Status authorize(SessionRegistry& registry, grpc::CallbackServerContext& context, const std::string& id,
                       Role needed, std::shared_ptr<Session>* session);

}  // namespace filigree::server
