#pragma once
// The Filigree C++ client: what a game engine links (CMake: filigree::client).
//
// Every call is blocking (gRPC's synchronous API): call them from your own
// threads. Failed calls throw ClientError carrying the gRPC status code.
// Typical use:
//
//   filigree::Client client("127.0.0.1:50051");
//   auto session = client.create_session(bytes, "obj", {}, "my-engine");
//   filigree::FrameDecoder decoder(session.mesh.rest_positions);
//   auto driver = client.drive(session.session_id, session.editor_token, "my-engine");
//   driver->send(1, pose);                       // writer thread, every tick
//   while (auto frame = driver->read())          // reader thread
//     upload_to_gpu(decoder.decode(*frame).positions);
//   driver->writes_done(); /* join reader */ driver->finish();
//
// The generated types (filigree::v1::…, "filigree/v1/filigree.pb.h") are the
// contract; stub() gives the raw gRPC stub for anything not wrapped here.

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "filigree/call_metadata.h"
#include "filigree/client_error.h"
#include "filigree/driver.h"
#include "filigree/edit_outcome.h"
#include "filigree/frame_decoder.h"
#include "filigree/history_export.h"
#include "filigree/presence_pointer.h"
#include "filigree/presence_watcher.h"
#include "filigree/session_mesh.h"
#include "filigree/v1/filigree.grpc.pb.h"
#include "filigree/watcher.h"

namespace filigree {

// A session made by create_session(). The editor token may drive, close and
// change options; the viewer token may join, watch and read state.
struct SessionHandle {
  std::string session_id;
  std::string editor_token;
  std::string viewer_token;
  bool cached = false;  // the server had preprocessed this mesh before
  SessionMesh mesh;     // what join() would return, without a second request
};

// How Client::play_clip() plays a clip (PlayClipRequest's fields). The
// server refuses (INVALID_ARGUMENT, from finish()) a speed or max_rate that
// is negative or not finite, and a start_seconds that is not finite.
struct ClipPlayback {
  double speed = 1.0;          // playback rate; 0 means 1
  bool loop = false;           // until the stream is cancelled
  double start_seconds = 0.0;  // clip time of the first sample
  double max_rate = 0.0;       // samples per second at most; 0: as fast as frames compute, up to 60
};

// Upload progress: stage "uploading" (bytes sent), then the server's stages
// ("validating", "simplifying", "starting"); fraction is 0…1 within a stage.
using ProgressCallback = std::function<void(const std::string& stage, double fraction)>;

class Client {
 public:
  // An insecure channel to `target` ("127.0.0.1:50051", "dns:///host:port")
  // with no limit on received message size (a SessionInfo of a large mesh is
  // tens of MiB). Connects lazily: a server that is down makes the first
  // call fail with UNAVAILABLE.
  explicit Client(const std::string& target);
  // The same channel settings with other credentials (TLS: grpc::SslCredentials).
  Client(const std::string& target, const std::shared_ptr<grpc::ChannelCredentials>& credentials);
  // Any channel (custom arguments).
  explicit Client(std::shared_ptr<grpc::Channel> channel);

  // Uploads `mesh_bytes` (a file of `format`: "obj", "ply", "off", "gltf",
  // "glb") in 1 MiB chunks and waits while the server preprocesses it.
  SessionHandle create_session(const std::string& mesh_bytes, const std::string& format,
                               const v1::SessionOptions& options, const std::string& client_name,
                               const ProgressCallback& progress = {});

  // The session's base and rest mesh (editor or viewer token).
  SessionMesh join(const std::string& session_id, const std::string& token);
  // The merged pose and the current frame, chunked: a FrameDecoder decodes
  // state.keyframe() first when the frame is sparse (has_keyframe()).
  v1::SessionState state(const std::string& session_id, const std::string& token);
  // Changes the cut threshold (editor token); whole_mesh means T = ∞.
  // `client_name` is the history entry's author.
  void set_threshold(const std::string& session_id, const std::string& token, double threshold, bool whole_mesh,
                     const std::string& client_name = {});
  // Replaces `client_name`'s handles (editor token): detailed-mesh vertex
  // `vertices[i]` (session order) should go to `targets[i]`. An empty set
  // removes that client's handles. Returns every participant's handle count.
  // Calls of one drag share a nonzero `gesture_id`: one history entry,
  // undone as one (0: calls less than 0.5 s apart are one entry).
  std::uint32_t set_handles(const std::string& session_id, const std::string& token, const std::string& client_name,
                            std::span<const std::uint32_t> vertices, std::span<const std::array<float, 3>> targets,
                            std::uint64_t gesture_id = 0);
  // One pose, unary (editor token): 3·m floats, base order, as Driver::send
  // but without a stream, with `client_name` as its author (a replay names
  // each pose's). Poses of one nonzero `gesture_id` are one history entry.
  // Returns the session's version when it was accepted: the frame that
  // includes it has a larger one.
  std::uint64_t submit_pose(const std::string& session_id, const std::string& token, const std::string& client_name,
                            std::span<const float> positions, std::uint64_t gesture_id = 0);
  // Ends the session for everyone (editor token).
  void close(const std::string& session_id, const std::string& token);
  // The server's sessions (no token needed; with replicas, this replica's).
  std::vector<v1::ListSessionsResponse::Entry> list();
  // Which replica serves the session, and its address: for engines that
  // route themselves instead of through a load balancer. Needs a token of
  // the session (or this client's API key owning it); anyone else is told
  // NOT_FOUND, as for an unknown id.
  v1::SessionLocation locate(const std::string& session_id, const std::string& token);

  // Opens a Drive stream (editor token). `client_name` is shown to others in
  // Frame.changes. The stream's failures show in send()/read()/finish().
  // It reconnects by itself after UNAVAILABLE, re-sending the poses no frame
  // acknowledged, as `reconnect` says (Driver).
  std::unique_ptr<Driver> drive(const std::string& session_id, const std::string& token,
                                const std::string& client_name, Reconnect reconnect = {});
  // The same with options: a level of detail for the frames that answer
  // (DriveOptions::max_vertices; Driver::set_detail changes it).
  std::unique_ptr<Driver> drive(const std::string& session_id, const std::string& token,
                                const std::string& client_name, const DriveOptions& options, Reconnect reconnect = {});
  // Opens a Watch stream (either token): frames newer than after_version.
  // It reconnects by itself after UNAVAILABLE (a restart, a failover) as
  // `reconnect` says; with reconnect.enabled false it ends there instead.
  std::unique_ptr<Watcher> watch(const std::string& session_id, const std::string& token,
                                 std::uint64_t after_version = 0, Reconnect reconnect = {});
  // The same with options: after_version, and a level of detail
  // (WatchOptions::max_vertices; Watcher::set_detail changes it):
  //   auto watcher = client.watch(id, token, filigree::WatchOptions{.max_vertices = 4096});
  std::unique_ptr<Watcher> watch(const std::string& session_id, const std::string& token, const WatchOptions& options,
                                 Reconnect reconnect = {});

  // Plays the session's clip `clip` (SessionMesh::skeleton.clips) on the
  // server (editor token): the returned stream carries the frames, as a
  // Drive stream does, and ends after the clip's last sample unless looping.
  // Each frame's pose_id numbers the newest sample it includes and its
  // clip_seconds (DecodedFrame::clip_seconds) is that sample's clip time:
  // from start_seconds up to the clip's duration, which the last frame
  // shows (a looping clip wraps around to 0 instead).
  std::unique_ptr<Watcher> play_clip(const std::string& session_id, const std::string& token, const std::string& clip,
                                     const ClipPlayback& playback = {}, const std::string& client_name = "clip");
  // ---- working together: the history, undo, checkpoints, presence, export.
  // Every accepted change is a history entry of its author (the client_name
  // of the poses, handles or threshold); a gesture (Driver::set_gesture, a
  // set_handles gesture_id) is one entry.

  // The history, oldest first, and the checkpoints (either token); `newest`
  // > 0: only the newest that many entries.
  v1::History history(const std::string& session_id, const std::string& token, std::uint32_t newest = 0);
  // Undoes `client_name`'s latest change not undone (editor token), on the
  // base vertices nobody else changed since: the others' later work stays
  // (EditOutcome::conflicts) unless `force`. Never another author's change.
  EditOutcome undo(const std::string& session_id, const std::string& token, const std::string& client_name,
                   bool force = false);
  // Redoes `client_name`'s latest undone change (since its last new one).
  EditOutcome redo(const std::string& session_id, const std::string& token, const std::string& client_name,
                   bool force = false);
  // Names the current pose and threshold (editor token); `name`: 1 to 200
  // characters. Checkpoints are listed in history().checkpoints().
  v1::Checkpoint create_checkpoint(const std::string& session_id, const std::string& token, const std::string& name,
                                   const std::string& client_name);
  // Goes back to checkpoint `checkpoint` (editor token): itself a history
  // entry of `client_name`, so undo() takes it back. NOT_FOUND: no such checkpoint.
  EditOutcome restore_checkpoint(const std::string& session_id, const std::string& token, std::uint64_t checkpoint,
                                 const std::string& client_name);
  // The current base pose against checkpoint `checkpoint` (either token).
  v1::CheckpointDiff diff_checkpoint(const std::string& session_id, const std::string& token, std::uint64_t checkpoint);
  // Who is here and what they touch (either token): a stream of Presence
  // snapshots, on which `client_name` is listed as present while it is open.
  std::unique_ptr<PresenceWatcher> watch_presence(const std::string& session_id, const std::string& token,
                                                  const std::string& client_name, Reconnect reconnect = {});
  // Sets `client_name`'s pointer, shown in the others' presence (either
  // token); nullopt clears it.
  void set_presence(const std::string& session_id, const std::string& token, const std::string& client_name,
                    const std::optional<PresencePointer>& pointer);
  // The state after each history entry from `from_entry` to `to_entry` (0:
  // the oldest kept, the newest), oldest first (either token), decoded
  // against `rest_positions` (SessionMesh::rest_positions). At most 2000
  // entries at a time (else the stream ends with INVALID_ARGUMENT).
  std::unique_ptr<HistoryExport> export_history(const std::string& session_id, const std::string& token,
                                                std::vector<float> rest_positions, std::uint64_t from_entry = 0,
                                                std::uint64_t to_entry = 0);

  // Routing::kDirect for an engine that calls the replica locate() named
  // instead of a load balancer (default: kLoadBalanced).
  void set_routing(Routing routing) { routing_ = routing; }
  // The API key CreateSession and ListSessions present (x-filigree-api-key)
  // to a server started with --api-keys; empty (the default): none.
  void set_api_key(std::string key) { api_key_ = std::move(key); }
  // How long a unary call (join, state, options, handles, close, list,
  // locate, a stream's set_detail) may take before it fails with DEADLINE_EXCEEDED, so a server
  // that hangs (frozen, partitioned) cannot block the caller forever.
  // Uploads and streams are not bounded by it. Default 60 s.
  void set_call_timeout(std::chrono::milliseconds timeout) { call_timeout_ = timeout; }

  v1::Filigree::Stub& stub() { return *stub_; }

 private:
  // A rest mesh too large for one message (RestMesh.in_parts): reads it
  // with GetRestMesh into `info`. ClientError DATA_LOSS if the parts do not
  // add up to the counts the summary gives.
  void read_rest_in_parts(const std::string& session_id, const std::string& token, v1::SessionInfo& info);

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
  Routing routing_ = Routing::kLoadBalanced;
  std::chrono::milliseconds call_timeout_{60000};
  std::string api_key_;
};

}  // namespace filigree
