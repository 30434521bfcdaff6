#pragma once
// One session's driver: full poses at a fixed rate on one thread, the Drive
// stream's frames read on another, and the checks on what comes back.
//
// What "an acknowledged pose is lost" means here. Frames on a Drive stream
// name the newest pose of that stream they include (Frame.pose_id); poses
// that arrive while a frame computes are coalesced, so not every id is
// echoed, and a pose is acknowledged once a frame names its id or a later
// one. It is lost if
//   1. a frame names a smaller pose_id than an earlier frame did (pose_ids on
//      the stream never go backwards), or
//   2. a frame names a pose that was not sent yet (it would acknowledge
//      nothing real), or
//   3. after the last pose and a half-close, the stream does not end with OK
//      right after a frame naming the last pose (the server promises that
//      frame before it ends the stream), or
//   4. the session then does not reflect the last pose (checked by
//      SessionLoad: GetState's version is that frame's, its merged pose is
//      the last pose bit for bit, its frame's changes name the last pose; and
//      every watcher's final frame is that frame, naming the last pose).
// Frame versions on the stream never go backwards either.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bench/soak/failures.h"
#include "filigree/client.h"
#include "mesh/tri_mesh.h"

namespace filigree::soak {

struct DriverStats {
  std::uint64_t poses_sent = 0;
  std::uint64_t acknowledged = 0;  // the newest pose_id a frame named: it and every pose before it
  std::uint64_t frames = 0;
  std::uint64_t first_version = 0, last_version = 0;
  double frame_seconds = 0.0;  // from the first frame to the last
};

class PacedDriver {
 public:
  PacedDriver(Client& client, const SessionHandle& session, std::string name, double rate_hz, double phase,
              Failures& failures);
  ~PacedDriver();

  void start();
  // Stops posing; the posing thread then half-closes (returns at once).
  void stop_posing();
  // Waits (until `deadline`) for the stream to end after stop_posing() and
  // checks its end (criterion 3). Returns the version of the frame that
  // acknowledged the last pose, or nullopt when that failed.
  std::optional<std::uint64_t> finish(std::chrono::steady_clock::time_point deadline);

  const std::string& name() const { return name_; }
  std::uint64_t last_pose_id() const { return last_pose_id_; }  // after finish()
  const std::vector<float>& last_pose() const { return last_pose_; }  // after finish()
  DriverStats stats() const;

 private:
  void pose_loop();
  void read_loop();
  std::vector<float> pose(std::uint64_t id) const;

  Client& client_;
  const SessionHandle& session_;
  const std::string name_;
  const std::chrono::nanoseconds period_;
  const double phase_;
  Failures& failures_;
  std::unique_ptr<Driver> driver_;
  std::vector<Vec3> base_rest_;  // for the motion, made once

  // The newest pose id handed to send(): set before send(), so a frame can
  // never legitimately name a larger one.
  std::atomic<std::uint64_t> sent_{0};
  std::uint64_t last_pose_id_ = 0;  // pose thread; read after it is joined
  std::vector<float> last_pose_;

  mutable std::mutex mutex_;
  std::condition_variable changed_;
  bool stop_ = false;
  bool posing_done_ = false;  // the poser half-closed and left
  bool read_done_ = false;
  DriverStats stats_;
  std::optional<std::uint64_t> last_frame_pose_;  // pose_id of the stream's final frame
  std::uint64_t last_frame_version_ = 0;          // and its version
  std::chrono::steady_clock::time_point first_frame_at_, last_frame_at_;

  std::thread poser_, reader_;
};

}  // namespace filigree::soak
