#include "bench/soak/paced_driver.h"

#include <cmath>

#include "runtime/procedural_motion.h"

namespace filigree::soak {

using Clock = std::chrono::steady_clock;

PacedDriver::PacedDriver(Client& client, const SessionHandle& session, std::string name, double rate_hz, double phase,
                         Failures& failures)
    : client_(client), session_(session), name_(std::move(name)),
      period_(std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / rate_hz))), phase_(phase), failures_(failures),
      base_rest_(points_from_xyz(session.mesh.base_positions)) {}

PacedDriver::~PacedDriver() {
  stop_posing();
  if (poser_.joinable()) poser_.join();
  if (driver_) driver_->cancel();
  if (reader_.joinable()) reader_.join();
}

void PacedDriver::start() {
  // No reconnection: the server stays up, so a stream that breaks is a
  // failure to report (send() false, finish()'s status), not to hide.
  Reconnect no_reconnect;
  no_reconnect.enabled = false;
  driver_ = client_.drive(session_.session_id, session_.editor_token, name_, no_reconnect);
  reader_ = std::thread([this] { read_loop(); });
  poser_ = std::thread([this] { pose_loop(); });
}

std::vector<float> PacedDriver::pose(std::uint64_t id) const {
  // A whole-body bend going back and forth (about a 4 s cycle at 30 Hz):
  // every base vertex moves every frame, the heaviest case for the encoder.
  const double t = 0.5 + 0.5 * std::sin(0.05 * static_cast<double>(id) + phase_);
  const Pose p = procedural_pose(base_rest_, Motion::kBend, t);
  std::vector<float> out;
  out.reserve(3 * p.positions.size());
  for (const Vec3& v : p.positions)
    for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(v[k]));
  return out;
}

void PacedDriver::pose_loop() {
  auto next = Clock::now();
  for (std::uint64_t id = 1;; ++id) {
    std::vector<float> positions = pose(id);
    sent_.store(id);  // before send(): the reader may see the frame before send() returns
    if (!driver_->send(id, positions)) {
      failures_.add(name_ + ": the Drive stream ended while posing (pose " + std::to_string(id) + ")");
      break;
    }
    last_pose_id_ = id;
    last_pose_ = std::move(positions);
    {
      std::lock_guard lock(mutex_);
      ++stats_.poses_sent;
    }
    // The workload's pace. A loaded machine that falls behind sends the next
    // pose at once instead of a burst of the missed ones.
    next = std::max(next + period_, Clock::now());
    std::unique_lock lock(mutex_);
    if (changed_.wait_until(lock, next, [&] { return stop_; })) break;
  }
  driver_->writes_done();
  std::lock_guard lock(mutex_);
  posing_done_ = true;
  changed_.notify_all();
}

void PacedDriver::read_loop() {
  std::uint64_t newest_pose = 0, newest_version = 0;
  bool any = false;
  while (std::optional<v1::Frame> f = driver_->read()) {
    const auto now = Clock::now();
    const std::uint64_t sent = sent_.load();
    if (f->pose_id() < newest_pose)
      failures_.add(name_ + ": pose_id went backwards on the Drive stream, " + std::to_string(newest_pose) + " then " +
                    std::to_string(f->pose_id()) + " (version " + std::to_string(f->version()) + ")");
    if (f->pose_id() > sent)
      failures_.add(name_ + ": a frame names pose " + std::to_string(f->pose_id()) + " but only " + std::to_string(sent) +
                    " were sent");
    if (any && f->version() < newest_version)
      failures_.add(name_ + ": frame version went backwards on the Drive stream, " + std::to_string(newest_version) +
                    " then " + std::to_string(f->version()));
    newest_pose = std::max(newest_pose, f->pose_id());
    newest_version = std::max(newest_version, f->version());
    std::lock_guard lock(mutex_);
    if (!any) {
      stats_.first_version = f->version();
      first_frame_at_ = now;
    }
    any = true;
    ++stats_.frames;
    stats_.acknowledged = newest_pose;
    stats_.last_version = newest_version;
    last_frame_at_ = now;
    last_frame_pose_ = f->pose_id();
    last_frame_version_ = f->version();
  }
  std::lock_guard lock(mutex_);
  read_done_ = true;
  changed_.notify_all();
}

void PacedDriver::stop_posing() {
  std::lock_guard lock(mutex_);
  stop_ = true;
  changed_.notify_all();
}

std::optional<std::uint64_t> PacedDriver::finish(Clock::time_point deadline) {
  // The poser half-closes on its way out; a server that stopped reading
  // could keep it in send() (flow control), so it is waited for with a limit too.
  bool ended;
  {
    std::unique_lock lock(mutex_);
    ended = changed_.wait_until(lock, deadline, [&] { return posing_done_ && read_done_; });
  }
  if (!ended) {
    failures_.add(name_ + ": the Drive stream did not end in time after the last pose (never acknowledged)");
    driver_->cancel();
  }
  poser_.join();
  reader_.join();
  const grpc::Status status = driver_->finish();
  if (!ended) return std::nullopt;
  if (!status.ok()) {
    failures_.add(name_ + ": the Drive stream ended with " + status_code_name(status.error_code()) + ": " +
                  status.error_message());
    return std::nullopt;
  }
  std::lock_guard lock(mutex_);
  if (last_pose_id_ == 0) return last_frame_version_;  // nothing sent: nothing to acknowledge
  if (!last_frame_pose_ || *last_frame_pose_ != last_pose_id_) {
    failures_.add(name_ + ": the last pose " + std::to_string(last_pose_id_) + " was not acknowledged: the stream's final frame names " +
                  (last_frame_pose_ ? std::to_string(*last_frame_pose_) : std::string("nothing (no frame)")));
    return std::nullopt;
  }
  return last_frame_version_;
}

DriverStats PacedDriver::stats() const {
  std::lock_guard lock(mutex_);
  DriverStats s = stats_;
  s.frame_seconds = stats_.frames > 1 ? std::chrono::duration<double>(last_frame_at_ - first_frame_at_).count() : 0.0;
  return s;
}

}  // namespace filigree::soak
