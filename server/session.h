#pragma once
// One session: a hierarchy, its deformer, the merged pose of every driver, and
// the frames fanned out to every subscriber (DESIGN §3).
//
// Threading: submit() and subscribe() are called from gRPC threads; the
// frame work runs on the server's FrameScheduler, on this session's lane: one
// compute at a time per session (poses that arrive meanwhile are coalesced,
// newest write per base vertex wins), then the frame's chunks are quantized
// and encoded in parallel. A pipeline of two: the next frame computes while
// the previous one encodes, once the encoder has read its positions. Each
// subscriber has a mailbox of one, so a slow one skips frames without
// delaying anyone.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <utility>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "codec/frame_encoder.h"
#include "filigree/v1/filigree.pb.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer.h"  // FrameStats
#include "runtime/pose.h"
#include "server/frame_scheduler.h"
#include "server/edit_history.h"
#include "server/level_frames.h"
#include "server/presence_sink.h"
#include "server/serialized_frame.h"
#include "server/session_assets.h"
#include "server/session_record.h"

namespace filigree {
class HandleSolver;
struct Rig;
struct AnimationClip;
struct SkeletonPose;
}

namespace filigree::server {

enum class Role { kNone, kViewer, kEditor };

// A frame as published: encoded once, shared by every subscriber. Drivers
// learn which of their poses it includes from pose_of_driver.
struct PublishedFrame {
  v1::Frame frame;  // FRAME_FORMAT_CHUNKED
  // The keyframe `frame` is relative to; null when it is one itself.
  std::shared_ptr<const PublishedFrame> keyframe;
  // FRAME_FORMAT_SINGLE, encoded only while a subscriber wants it.
  std::shared_ptr<const v1::Frame> single;
  std::unordered_map<std::uint64_t, std::uint64_t> pose_of_driver;
  // The same frame at each level of detail a stream wanted when it was
  // computed, by the level's vertex count (proto DetailLevel).
  std::vector<std::pair<std::uint32_t, std::shared_ptr<const PublishedFrame>>> levels;
  // A frame at a level of detail: the level's mesh (null at full detail).
  std::shared_ptr<const LevelGeometry> geometry;
  // The frame at `level` (the full mesh's vertex count: this one), or null.
  const PublishedFrame* at_level(std::uint32_t level) const {
    if (level == frame.vertex_count()) return this;
    for (const auto& [vertices, f] : levels)
      if (vertices == level) return f.get();
    return nullptr;
  }
  // Where the wire bytes below are serialized (the mesh's pool).
  std::shared_ptr<BufferPool<char>> wire_pool;

  // The wire bytes of `frame` and of `single` (which must be set),
  // serialized by the first stream that writes each, then shared.
  const SerializedFrame& frame_bytes() const { return frame_wire_.get(frame, wire_pool); }
  const SerializedFrame& single_bytes() const { return single_wire_.get(*single, wire_pool); }

 private:
  LazySerializedFrame frame_wire_, single_wire_;
};

// Where a pose comes from: the driver stream (0: a unary call, no stream to
// answer), the client it names in frames' changes and its pose id.
// `keyframe`: the frame that first includes this pose is a keyframe.
struct PoseOrigin {
  std::uint64_t driver = 0;
  std::string client_name;
  std::uint64_t pose_id = 0;
  bool keyframe = false;
  std::uint64_t gesture = 0;  // DriveRequest.gesture_id: one history entry
};

// A subscriber's mailbox; implemented by the streaming reactors.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  // Called with every new frame, from the session's worker; must not block.
  // A chunked stream sends frame->keyframe first if it has not sent it.
  virtual void offer(std::shared_ptr<const PublishedFrame> frame) = 0;
  // Which frames this subscriber reads (fixed for its life).
  virtual v1::FrameFormat format() const = 0;
  // The driver whose poses this stream answers (PublishedFrame::pose_of_driver),
  // or 0 for a watcher (fixed for its life).
  virtual std::uint64_t driver() const { return 0; }
  // Streams at a level of detail (proto DetailLevel): their id for
  // SetDetail (0: a stream that asked for none, always at full detail) and
  // the level they want now (a vertex count; the full mesh's at full detail).
  virtual std::uint64_t stream_id() const { return 0; }
  virtual std::uint32_t level() const { return 0; }
  // Goes to `level` (one of Session::level_for's): the next frame offered is
  // written after the level's DetailLevel even if its version was written.
  virtual void switch_level(std::uint32_t /*level*/) {}
  // The session is closing (session_closed) or leaves this process (the
  // server stops, or the session moves to another replica): finish the
  // stream, with `why` as the UNAVAILABLE message in the second case.
  virtual void close(bool session_closed, const std::string& why) = 0;
};

// Where a session's changes are made durable before they are acknowledged.
// `write` is called with the session's progress before a unary change is
// answered (SubmitPose, handles, options) and before a frame is published;
// it throws to refuse it (the store is unreachable or full, or another
// replica owns the session now). Empty: no journal (memory only).
struct Journal {
  std::function<void(const SessionProgress&)> write;
  // Also before each streamed pose is merged, not only with the frame that
  // answers it: a shared store, where another replica may take the session
  // over between the merge and the frame. One machine journals with the
  // frame (a group commit of the poses it merges; DESIGN §3.3).
  bool every_merge = true;
  // Where the edit history goes (its serialized bytes, whole); empty: kept
  // in memory only.
  std::function<void(const std::string&)> write_history;
  explicit operator bool() const { return static_cast<bool>(write); }
};

class Session {
 public:
  // Computes the current frame; later frames run on `scheduler`, which must
  // outlive the session.
  Session(SessionRecord record, std::shared_ptr<const SessionAssets> assets, FrameScheduler& scheduler,
          Journal journal = {}, HistoryLimits history_limits = {});
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  const std::string& id() const { return record_.id; }
  // The API key that created the session (fixed at creation); empty without keys.
  const std::string& owner() const { return record_.owner; }
  // The key of its hierarchy in the HierarchyCache (fixed at creation).
  const std::string& hierarchy_key() const { return record_.hierarchy_key; }
  // Vertices of the detailed mesh.
  std::size_t vertex_count() const;
  Role authorize(const std::string& token) const;

  // Merges a full (indices empty) or partial pose from `driver` (0: a unary
  // call, no stream to name in frames). Throws
  // PoseError (→ INVALID_ARGUMENT) for a wrong length, an index out of range or
  // NaN/Inf, without changing anything. With a journal, returns once the
  // change is journaled, and throws what the journal throws (the change is
  // then merged here but not acknowledged).
  void submit(const PoseOrigin& origin, std::span<const std::uint32_t> indices, std::span<const float> positions);

  // Skeletal poses (sessions of a skinned upload). Merges `joints` into the
  // session's joint state, skins the base mesh with it (options.skinning)
  // and merges that as a full pose of `driver`, as submit() does; handles
  // are then solved again on top. Throws PoseError (→ INVALID_ARGUMENT)
  // without changing anything for a session without a skeleton, a joint out
  // of range or named twice, a wrong value count, NaN/Inf, a zero
  // quaternion or a matrix that is not affine.
  void submit_joints(const PoseOrigin& origin, const v1::JointPose& joints);
  // The clip called `name` of the session's rig, or null (none, or no rig).
  const AnimationClip* clip(const std::string& name) const;
  // Samples `clip` (one of clip()'s) at `seconds` into the joint state (the
  // joints it animates restart from their rest transform) and merges the
  // skinned base as submit_joints() does.
  void submit_clip_sample(const PoseOrigin& origin, const AnimationClip& clip, double seconds);
  bool has_skeleton() const { return rig_ != nullptr; }

  // Registers a subscriber; it is offered the current frame at once if its
  // version is newer than `after_version` (always, when that is nullopt).
  void subscribe(const std::shared_ptr<FrameSink>& sink, std::optional<std::uint64_t> after_version);
  void unsubscribe(const FrameSink* sink);
  // A driver's stream ended: it no longer counts as a driver.
  void driver_left(std::uint64_t driver);
  // The next frame is a keyframe (a client lost its decoded state).
  void request_keyframe();
  // The level of detail (its vertex count, the full mesh's at full detail)
  // that serves a budget of `max_vertices` ≥ 1 (hierarchy/detail_level.h).
  std::uint32_t level_for(std::uint32_t max_vertices) const;
  // Moves subscriber `stream_id` (FrameSink::stream_id) to the level that
  // serves `max_vertices` ≥ 1 and returns it; nullopt when no subscriber
  // has that id.
  std::optional<std::uint32_t> set_detail(std::uint64_t stream_id, std::uint32_t max_vertices);

  // Throws HierarchyError (and changes nothing) if a finite T is asked of a
  // hierarchy whose node graph cannot be derived. Returns the version when
  // the change was accepted: every frame with a larger version applies it,
  // and one follows. Recorded in the history as `author`'s unless null.
  std::uint64_t set_threshold(double threshold, bool whole_mesh, const std::string* author = nullptr);

  // The edit history (edit_history.h). Undo, redo and restore change the
  // pose (and handles, threshold) at once, journal it and answer with the
  // version every frame including it exceeds.
  v1::History history(std::size_t newest) const;
  v1::UndoResponse undo(const std::string& author, bool redo, bool force);
  // Throws std::invalid_argument for a bad name.
  v1::Checkpoint create_checkpoint(const std::string& author, const std::string& name);
  // Throws std::out_of_range for an unknown checkpoint.
  v1::UndoResponse restore_checkpoint(const std::string& author, std::uint64_t id);
  v1::CheckpointDiff diff_checkpoint(std::uint64_t id) const;
  // The base pose after each entry of [from, to] (EditHistory::states).
  std::vector<std::pair<v1::HistoryEntry, std::vector<float>>> history_states(std::uint64_t from, std::uint64_t to) const;
  // Each author's latest change: its base vertices and end time (presence).
  std::map<std::string, std::pair<std::vector<std::uint32_t>, double>> latest_changes() const;
  // Presence (proto Presence). A WatchPresence stream joins as `name` with
  // `role` and gets the current presence at once, then every change.
  struct Pointer {
    float x = 0, y = 0, z = 0;
    std::uint32_t vertex = 0;
  };
  void join_presence(const std::shared_ptr<PresenceSink>& sink, const std::string& name, Role role);
  void leave_presence(const PresenceSink* sink, const std::string& name);
  // Sets (nullopt: clears) `name`'s pointer.
  void point(const std::string& name, Role role, std::optional<Pointer> pointer);
  // Sends presence held back by pacing (the maintenance tick).
  void flush_presence();

  // Writes the history where the journal keeps it (Journal::write_history)
  // if it changed since the last write; a failure is logged and retried at
  // the next call. Called after undo, redo and checkpoints, at shutdown, and
  // by the registry's maintenance (`tick`) for the entries of gestures: then
  // only after a second without activity, or 10 s after the last write.
  void persist_history(bool tick = false);
  // Whether set_threshold(threshold, whole_mesh) would first derive the
  // mesh's node graph and region optimisation's data (once per mesh; ~1 s
  // at 1.25M vertices), or, for whole_mesh, make T = ∞'s factorisation
  // (seconds): callers keep such a call off threads that must stay
  // responsive.
  bool threshold_needs_preparation(double threshold, bool whole_mesh) const;
  // Replaces `client_name`'s handles (vertex ids of the detailed mesh and
  // targets); the next frame solves every client's handles into the base pose.
  // Throws PoseError for a vertex out of range or a non-finite target. With a
  // journal, returns once the handles are journaled, and throws what the
  // journal throws. Returns the number of handles in the session after the merge.
  std::size_t set_handles(const std::string& client_name, const std::vector<std::pair<Index, Vec3>>& handles,
                          std::uint64_t gesture = 0);
  // GetHandles' answer: every client's handles as set, by client name, and
  // the version of the newest frame.
  v1::SessionHandles handles() const;
  // Finishes every stream; the session computes nothing more.
  void close();
  // Leaves this process if no stream uses it, in one step with subscribe(),
  // merges and handle changes: those then refuse with StoreUnavailable (load
  // the session again) rather than change a copy nobody persists. False,
  // and nothing changes, while a stream is open.
  bool evict_if_unused();
  // Finishes every stream with UNAVAILABLE and `why` (the server shuts down,
  // the session moves); state stays.
  void close_streams(const std::string& why);
  // Why the session stopped computing here (its journal failed), or empty.
  std::string failure() const;

  // GetOverlays' answer as wire bytes: the overlays of the latest frame,
  // serialized once and shared by every caller, or `ready: false` (an
  // empty message) until a frame has them; asking keeps them built for 5 s.
  grpc::ByteBuffer overlays_wire();

  // The whole SessionInfo as a message: builds the rest mesh (36+ bytes per
  // vertex), for the one answer that is no raw method (CreateSession's).
  // A rest mesh over `inline_rest_most` bytes on the wire (with this
  // session's uploaded ids) is left out: RestMesh.in_parts, read with
  // GetRestMesh.
  v1::SessionInfo info(std::size_t inline_rest_most) const;
  // The same as wire bytes (session_info_wire.h), the mesh's shared;
  // `version` replaces the current version when given (SetOptions).
  grpc::ByteBuffer info_wire(std::size_t inline_rest_most, std::optional<std::uint64_t> version = std::nullopt) const;
  // The upload's vertex of each session vertex (RestMesh.uploaded_ids):
  // fixed at creation.
  std::span<const std::uint32_t> uploaded_ids() const { return record_.uploaded_ids; }
  // Its ListSessions entry: ids, counts, version, streams; no mesh copied.
  void describe(v1::ListSessionsResponse::Entry& entry) const;
  // GetState's answer as wire bytes: the merged pose and the current frame
  // in `format` (with its keyframe when chunked and sparse), the frames'
  // bytes shared with the streams that send them. A single buffer not made
  // yet is transcoded here first (tens of ms at 1.25M vertices); throws
  // DeltaCodecError if that fails.
  grpc::ByteBuffer state_wire(v1::FrameFormat format);
  // Whether answering or subscribing in `format` transcodes the current frame
  // first: FRAME_FORMAT_SINGLE, and the frame has no single buffer yet
  // (hundreds of ms at 1.25M vertices; callers keep that off gRPC's callback
  // threads).
  bool needs_single(v1::FrameFormat format) const;
  // With the handles and, for an adaptive cut, the cut of the latest frame
  // (O(nodes): waits for a frame computing now).
  SessionRecord record() const;
  // What of record() changes while the session runs, without copying what
  // never does (the upload's ids are 4 bytes per vertex).
  SessionProgress progress() const;
  const SessionAssets& assets() const { return *assets_; }
  std::shared_ptr<const PublishedFrame> current_frame() const;

  std::size_t subscriber_count() const;
  // Seconds since the last request or frame.
  double idle_seconds() const;
  std::uint64_t version() const;
  // A version that every frame including a change made now will exceed: the
  // current version, plus one while a frame (that missed the change) computes.
  std::uint64_t accepted_version() const;
  std::size_t drivers() const;

 private:
  [[noreturn]] void throw_evicted() const;  // mutex_ held
  // info()'s fields but the meshes (base, rest).
  v1::SessionInfo own_info() const;
  // Handles not yet solved into record_.pose (mutex_ held).
  bool handles_pending_locked() const { return handles_dirty_ || handles_solving_; }
  // A frame between compute and publication.
  struct InFlight {
    std::uint64_t version = 0;
    FrameStats stats;
    std::unordered_map<std::uint64_t, std::uint64_t> pose_of_driver;
    std::map<std::string, v1::Change> changes;
    std::shared_ptr<v1::Overlays> overlays;
    bool force_keyframe = false, single = false;
    std::size_t chunk_parts = 1;  // tasks the chunks are encoded in
    std::chrono::steady_clock::time_point encode_start{};
    // The single buffer (FRAME_FORMAT_SINGLE), when one is made.
    std::vector<float> single_values;
    DeltaQuantization single_quantization;
    double single_error = 0.0;
    std::string single_bytes;
    // The levels of detail streams want (their geometry), encoded in a
    // part of their own; a level whose encoding failed is left out.
    std::vector<std::shared_ptr<const LevelGeometry>> levels;
    std::vector<std::uint32_t> levels_failed;
    std::atomic<bool> failed{false};
  };
  enum class PartKind { kChunks, kSingle, kLevels };
  static PartKind part_kind(const InFlight& f, std::size_t p);
  // The levels the subscribers want now, but the full mesh (mutex_ held).
  std::vector<std::uint32_t> wanted_levels_locked() const;
  // A frame with every wanted level is computed unless the current one has
  // them (mutex_ held).
  void compute_if_level_missing_locked();

  // The session's first frame (the rest mesh, or the restored pose),
  // computed and encoded on the caller's thread, then published.
  void encode_first_frame();
  // Computes the merged pose into frame_ (and overlays); false when nothing
  // may be published (the journal failed, or the compute did).
  bool compute_frame(InFlight& f, bool keep_version);
  // Starts encoding computed_ (mutex_ held): posts its chunks.
  void start_encode_locked();
  // Posts a compute if a change waits and frame_ is free (mutex_ held).
  void maybe_compute_locked();
  // Hands frame_ back to the mesh's pool: only when nothing reads it until
  // the next compute (every part quantized, or the compute failed).
  void release_frame();
  void compute_task();
  // Part p of a frame's encoding: the p-th of f.chunk_parts even runs of
  // chunks, or the single buffer (p == f.chunk_parts). Quantizing reads
  // frame_; encoding does not.
  std::pair<std::size_t, std::size_t> chunks_of_part(const InFlight& f, std::size_t p) const;
  void quantize_part_of(InFlight& f, std::size_t p);
  void encode_part_of(InFlight& f, std::size_t p);
  void part_task(InFlight* f, std::size_t p);
  // Whether frames should carry the single buffer now (mutex_ held).
  bool want_single_locked() const;
  // `frame` with a single buffer transcoded from its chunks (decoded as a
  // client would, encoded as one buffer); becomes the current frame if
  // `frame` was. Throws DeltaCodecError if the frame cannot be decoded.
  std::shared_ptr<const PublishedFrame> with_single(const std::shared_ptr<const PublishedFrame>& frame);
  // Skins the base with joint_pose_ and merges it (skeleton_mutex_ held).
  void submit_skinned_locked(const PoseOrigin& origin);
  // Merges a validated pose; `skinned` re-solves handles on top of it.
  // Throws PoseError if a posed coordinate lies beyond SessionAssets::pose_reach,
  // naming it as `what` `index` ("pose coordinate 7").
  void check_reach(double coordinate, const char* what, std::size_t index) const;
  void merge(const PoseOrigin& origin, std::span<const std::uint32_t> indices, std::span<const float> positions,
             bool skinned);
  // Builds and publishes the encoded frame.
  void publish(InFlight& f);
  void touch();
  // An undo, redo or restore's outcome applied (mutex_ held): handles,
  // the pose's frame, the journal's progress; returns the journal seq.
  std::uint64_t apply_history_locked(const std::string& author, const HistoryOutcome& outcome, SessionProgress& progress);
  // An undo, redo or restore: `act` (under mutex_) changes record_.pose
  // through the history; what it did is applied, journaled and answered.
  v1::UndoResponse change_by_history(const std::string& author,
                                     const std::function<HistoryOutcome(const ChangeOrigin&)>& act);
  // Finishes an undo, redo or restore: journal, threshold, answer's version.
  v1::UndoResponse finish_history(HistoryOutcome outcome, std::uint64_t seq, SessionProgress& progress,
                                  std::uint64_t accepted);
  double threshold_locked() const;  // +inf for whole-mesh optimisation
  // Journals `progress` unless a later progress (by seq) already was.
  void journal(const SessionProgress& progress, std::uint64_t seq);
  // The progress including a change just merged, under the version of the frame that will show it.
  SessionProgress progress_with_change_locked() const;
  // Every client's handles as kept, oldest first (mutex_ held).
  std::vector<SessionHandle> handles_locked() const;
  // Frames assigned a version but not published yet.
  std::uint64_t in_flight_locked() const { return assigned_version_ - record_.version; }

  const std::shared_ptr<const SessionAssets> assets_;  // shared by every session of the mesh
  // record_.uploaded_ids as RestMesh wire bytes, made by the first ids_wire().
  const grpc::Slice& ids_wire() const;
  mutable std::once_flag ids_wire_once_;
  mutable grpc::Slice ids_wire_;
  // The base mesh's rig and the joint state skeletal poses merge into; null
  // without a skinned upload. skeleton_mutex_ orders skeletal poses (taken
  // before mutex_, never after).
  std::unique_ptr<const Rig> rig_;
  v1::Skeleton skeleton_info_;
  std::mutex skeleton_mutex_;
  std::unique_ptr<SkeletonPose> joint_pose_;
  std::vector<Vec3> skinned_positions_;  // the skinned base (skeleton_mutex_ held)
  std::vector<float> skinned_;  // the same as floats, for merge()
  // cut_mutex_ guards what record() reads of the deformer (its cut) against
  // the compute changing it; taken before mutex_, never after.
  mutable std::mutex cut_mutex_;
  std::unique_ptr<Deformer> deformer_;
  std::unique_ptr<HandleSolver> handle_solver_;
  FrameScheduler& scheduler_;
  std::shared_ptr<FrameScheduler::Lane> lane_;
  Pose scratch_pose_;        // compute_frame's buffers (one compute at a time)
  std::vector<Vec3> frame_;  // positions of the frame computed last, from compute to quantization (empty between)
  FrameEncoder encoder_;
  // Each level of detail's encoder, while streams want it (touched by the
  // encoding frame's levels part and publish(), one frame at a time).
  std::map<std::uint32_t, std::unique_ptr<LevelFrames>> level_frames_;
  std::map<std::uint32_t, std::uint64_t> level_frames_encoded_;  // mutex_; for ListSessions
  std::set<std::uint32_t> levels_building_;
  EditHistory history_;  // mutex_
  std::chrono::steady_clock::time_point history_saved_{};  // mutex_
  // Presence (session_presence.cpp), mutex_.
  struct PresenceState {
    Role role = Role::kNone;
    int streams = 0;  // WatchPresence streams open under this name
    std::optional<Pointer> pointer;
    std::chrono::steady_clock::time_point active{};
  };
  std::map<std::string, PresenceState> presence_;
  std::vector<std::weak_ptr<PresenceSink>> presence_sinks_;
  bool presence_dirty_ = false;
  std::chrono::steady_clock::time_point presence_published_{};
  v1::Presence presence_locked() const;
  // Offers the presence to every stream; `paced`: not within 100 ms of the
  // last (then the next event or tick sends it).
  void publish_presence_locked(bool paced);
  // Who set handles last: the handle solve's pose change is theirs (mutex_).
  ChangeOrigin handles_origin_;                      // mutex_: meshes being built for this session
  std::unique_ptr<InFlight> computed_;  // computed, waiting for the encoder
  std::unique_ptr<InFlight> encoding_;  // being encoded

  mutable std::mutex mutex_;
  SessionRecord record_;
  bool pending_ = false, stopping_ = false, closed_ = false, computing_ = false;
  std::uint64_t assigned_version_ = 0;  // the newest frame's version, published or not
  std::size_t positions_busy_ = 0;      // parts of the encoding frame still reading frame_
  std::size_t parts_left_ = 0;          // parts of the encoding frame not encoded yet
  // Asked for by a client: the next frame to read the pose is a keyframe
  // (taken at compute, with the pose it goes with).
  bool keyframe_requested_ = false;
  // The encoder must send a keyframe next (a frame failed to encode).
  bool keyframe_needed_ = false;
  std::shared_ptr<const PublishedFrame> keyframe_;
  std::optional<double> pending_threshold_;
  // A deformer that made T = ∞'s shared factorisations in set_threshold,
  // holding them until the frame that applies that threshold has found them.
  std::unique_ptr<Deformer> warm_;
  std::unordered_map<std::uint64_t, std::uint64_t> latest_pose_of_driver_;
  std::map<std::string, v1::Change> changes_;  // since the last frame, by client
  // The base vertices each client's changes_ entry counts: a vertex moved by
  // several merged poses of one client counts once.
  std::map<std::string, std::vector<bool>> touched_;
  struct HandleEntry {
    Vec3 target;
    std::string client;
    std::uint64_t stamp;  // newest wins per vertex
  };
  std::map<Index, std::vector<HandleEntry>> handles_;  // by vertex
  std::uint64_t handle_stamp_ = 0;
  bool handles_dirty_ = false;
  // Handles being solved by the frame computing now: not yet in record_.pose,
  // so a record written meanwhile must still say they are pending.
  bool handles_solving_ = false;
  bool evicted_ = false;  // by evict_if_unused(): requests must go to a fresh copy
  std::vector<std::weak_ptr<FrameSink>> sinks_;
  std::shared_ptr<const PublishedFrame> current_;
  std::shared_ptr<const SerializedOnce> overlays_;  // the current frame's, if it has them
  std::chrono::steady_clock::time_point overlays_wanted_until_{};
  std::chrono::steady_clock::time_point last_activity_;
  const Journal journal_;
  std::mutex journal_mutex_;
  std::uint64_t journal_seq_ = 0;    // changes merged (mutex_)
  std::uint64_t journaled_seq_ = 0;  // changes journaled (journal_mutex_)
  std::string failure_;
};

}  // namespace filigree::server
