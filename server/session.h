#pragma once
// One session: a hierarchy, its deformer, the merged pose of every driver, and
// the frames fanned out to every subscriber (DESIGN §3).
//
// Threading: submit() and subscribe() are called from gRPC threads; one
// worker thread per session computes, so there is one compute at a time per
// session, and poses that arrive meanwhile are coalesced (newest write per base
// vertex wins). Each subscriber has a mailbox of one, so a slow one skips
// frames without delaying anyone.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "filigree/v1/filigree.pb.h"
#include "hierarchy/hierarchy.h"
#include "runtime/pose.h"
#include "server/session_assets.h"
#include "server/session_record.h"

namespace filigree {
class Deformer;
class HandleSolver;
}

namespace filigree::server {

enum class Role { kNone, kViewer, kEditor };

// A frame as published: encoded once, shared by every subscriber. Drivers
// learn which of their poses it includes from pose_of_driver.
struct PublishedFrame {
  v1::Frame frame;
  std::unordered_map<std::uint64_t, std::uint64_t> pose_of_driver;
};

// A subscriber's mailbox; implemented by the streaming reactors.
class FrameSink {
 public:
  virtual ~FrameSink() = default;
  // Called with every new frame, from the session's worker; must not block.
  virtual void offer(std::shared_ptr<const PublishedFrame> frame) = 0;
  // The session is closing (session_closed) or leaves this process (the
  // server stops, or the session moves to another replica): finish the
  // stream, with `why` as the UNAVAILABLE message in the second case.
  virtual void close(bool session_closed, const std::string& why) = 0;
};

// Called with the session's progress before a change is acknowledged (a
// SubmitPose answered, a frame published); throws to refuse it (the shared
// store is unreachable, or another replica owns the session now). Empty: no
// journal (one machine: the registry writes records periodically).
using Journal = std::function<void(const SessionProgress&)>;

class Session {
 public:
  // Computes the current frame, then starts the worker.
  Session(SessionRecord record, std::shared_ptr<const SessionAssets> assets, Journal journal = {});
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  const std::string& id() const { return record_.id; }
  Role authorize(const std::string& token) const;

  // Merges a full (indices empty) or partial pose from `driver` (0: a unary
  // call, no stream to name in frames). Throws
  // PoseError (→ INVALID_ARGUMENT) for a wrong length, an index out of range or
  // NaN/Inf, without changing anything. With a journal, returns once the
  // change is journaled, and throws what the journal throws (the change is
  // then merged here but not acknowledged).
  void submit(std::uint64_t driver, const std::string& client_name, std::uint64_t pose_id,
              std::span<const std::uint32_t> indices, std::span<const float> positions);

  // Registers a subscriber; it is offered the current frame at once if its
  // version is newer than `after_version` (always, when that is nullopt).
  void subscribe(const std::shared_ptr<FrameSink>& sink, std::optional<std::uint64_t> after_version);
  void unsubscribe(const FrameSink* sink);
  // A driver's stream ended: it no longer counts as a driver.
  void driver_left(std::uint64_t driver);

  void set_threshold(double threshold, bool whole_mesh);
  // Replaces `client_name`'s handles (vertex ids of the detailed mesh and
  // targets); the next frame solves every client's handles into the base pose.
  // Throws PoseError for a vertex out of range or a non-finite target.
  // Returns the number of handles in the session after the merge.
  std::size_t set_handles(const std::string& client_name, const std::vector<std::pair<Index, Vec3>>& handles);
  // Finishes every stream; the session computes nothing more.
  void close();
  // Finishes every stream with UNAVAILABLE and `why` (the server shuts down,
  // the session moves); state stays.
  void close_streams(const std::string& why);
  // Why the session stopped computing here (its journal failed), or empty.
  std::string failure() const;

  // The overlays of the latest frame; asking keeps them built for 5 s.
  v1::Overlays overlays();

  v1::SessionInfo info() const;
  v1::SessionState state() const;
  SessionRecord record() const;
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
  void run();
  // Computes and publishes a frame of the current merged pose; the version
  // grows by one unless `keep_version` (the frame made when (re)loading).
  void compute_once(bool keep_version);
  void touch();
  // Journals `progress` unless a later progress (by seq) already was.
  void journal(const SessionProgress& progress, std::uint64_t seq);
  // The progress including a change just merged, under the version of the frame that will show it.
  SessionProgress progress_with_change_locked() const;

  const std::shared_ptr<const SessionAssets> assets_;  // shared by every session of the mesh
  std::unique_ptr<Deformer> deformer_;
  std::unique_ptr<HandleSolver> handle_solver_;
  Pose scratch_pose_;       // compute_once's buffers (worker thread only)
  std::vector<Vec3> frame_;  // positions, then deltas in place

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  SessionRecord record_;
  bool pending_ = false, stopping_ = false, closed_ = false, computing_ = false;
  std::optional<double> pending_threshold_;
  std::unordered_map<std::uint64_t, std::uint64_t> latest_pose_of_driver_;
  std::map<std::string, v1::Change> changes_;  // since the last frame, by client
  struct HandleEntry {
    Vec3 target;
    std::string client;
    std::uint64_t stamp;  // newest wins per vertex
  };
  std::map<Index, std::vector<HandleEntry>> handles_;  // by vertex
  std::uint64_t handle_stamp_ = 0;
  bool handles_dirty_ = false;
  std::vector<std::weak_ptr<FrameSink>> sinks_;
  std::shared_ptr<const PublishedFrame> current_;
  std::shared_ptr<const v1::Overlays> overlays_;
  std::chrono::steady_clock::time_point overlays_wanted_until_{};
  std::chrono::steady_clock::time_point last_activity_;
  const Journal journal_;
  std::mutex journal_mutex_;
  std::uint64_t journal_seq_ = 0;    // changes merged (mutex_)
  std::uint64_t journaled_seq_ = 0;  // changes journaled (journal_mutex_)
  std::string failure_;
  std::thread worker_;
};

}  // namespace filigree::server
