#pragma once
// One of a session's three watchers, each of a kind:
//   normal        reads and decodes every frame as it comes;
//   slow          sleeps after each frame (longer than the frame period), so
//                 the server's mailbox of one makes it skip frames (on a
//                 connection with a small HTTP/2 window, SessionLoad: else
//                 megabytes of frames wait in the transport before the
//                 server has anything to skip);
//   reconnecting  cancels its stream every few seconds and opens a new one
//                 with after_version = the newest version it received.
// Checks: frame versions never go backwards within a stream; after a resume
// only a keyframe (keyframe_version == version, sent so that decoding can go
// on) may be as old as after_version, every other frame must be newer; every
// frame decodes (FrameDecoder, one per watcher, kept across resumes); a
// stream ends only when this program ends it (CANCELLED after cancel()).
// The library's own reconnection is off: the server stays up, so any other
// end is an error to report, not to recover from.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <thread>

#include "bench/soak/failures.h"
#include "filigree/client.h"

namespace filigree::soak {

// The pose of client `name` that `frame` includes, from its changes (0: none).
std::uint64_t pose_in_changes(const v1::Frame& frame, const std::string& name);

enum class WatcherKind { kNormal, kSlow, kReconnecting };
const char* to_string(WatcherKind kind);

struct WatcherStats {
  std::uint64_t frames = 0;
  std::uint64_t skipped = 0;     // versions it never received (between ones it did)
  std::uint64_t reconnects = 0;  // deliberate resumes
  std::uint64_t newest_version = 0;
  // The driver's pose named in the changes of the newest frame (0: none).
  std::uint64_t newest_driver_pose = 0;
  std::uint64_t max_lag = 0;  // versions behind the driver when a frame was read (slow watcher)
};

class SoakWatcher {
 public:
  // `newest_version`: the newest version the session's driver has seen; a
  // slow watcher's frames may be at most `lag_limit` versions older when it
  // reads them (the library's watcher follows with acknowledgements, on a
  // channel of default settings).
  SoakWatcher(Client& client, const SessionHandle& session, WatcherKind kind, std::string driver_name,
              std::chrono::milliseconds slow_delay, std::chrono::milliseconds reconnect_every, Failures& failures,
              std::function<std::uint64_t()> newest_version = {}, std::uint64_t lag_limit = 0);
  ~SoakWatcher();

  void start();
  // Waits (until `deadline`) for a frame of version ≥ `version`; false if
  // none came (or the watcher ended).
  bool wait_for_version(std::uint64_t version, std::chrono::steady_clock::time_point deadline);
  // The load is over: the slow watcher stops sleeping, so that it reaches the
  // final frame without first reading out what its transport holds.
  void end_delay() { delay_ended_ = true; }
  // Cancels the stream and joins.
  void stop();

  WatcherKind kind() const { return kind_; }
  const std::string& name() const { return name_; }
  WatcherStats stats() const;

 private:
  void run();
  // Takes one frame; false to end this stream (a deliberate reconnect is due).
  bool take(const v1::Frame& frame, FrameDecoder& decoder, std::uint64_t resumed_after, std::uint64_t& stream_newest,
            bool& stream_any, std::chrono::steady_clock::time_point opened);

  Client& client_;
  const SessionHandle& session_;
  const WatcherKind kind_;
  const std::string name_, driver_name_;
  const std::chrono::milliseconds slow_delay_, reconnect_every_;
  Failures& failures_;
  const std::function<std::uint64_t()> newest_version_;
  const std::uint64_t lag_limit_;
  std::atomic<bool> delay_ended_{false};

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  bool stopping_ = false;
  bool ended_ = false;
  Watcher* current_ = nullptr;  // the open stream, for stop() to cancel
  WatcherStats stats_;
  std::thread thread_;
};

}  // namespace filigree::soak
