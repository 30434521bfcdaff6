#include "bench/soak/soak_watcher.h"

namespace filigree::soak {

std::uint64_t pose_in_changes(const v1::Frame& frame, const std::string& name) {
  for (const v1::Change& c : frame.changes())
    if (c.client_name() == name) return c.pose_id();
  return 0;
}

using Clock = std::chrono::steady_clock;

const char* to_string(WatcherKind kind) {
  switch (kind) {
    case WatcherKind::kNormal: return "normal";
    case WatcherKind::kSlow: return "slow";
    case WatcherKind::kReconnecting: return "reconnecting";
  }
  return "?";
}

SoakWatcher::SoakWatcher(Client& client, const SessionHandle& session, WatcherKind kind, std::string driver_name,
                         std::chrono::milliseconds slow_delay, std::chrono::milliseconds reconnect_every, Failures& failures,
                         std::function<std::uint64_t()> newest_version, std::uint64_t lag_limit)
    : client_(client), session_(session), kind_(kind),
      name_(driver_name + "/" + to_string(kind) + " watcher"), driver_name_(std::move(driver_name)),
      slow_delay_(slow_delay), reconnect_every_(reconnect_every), failures_(failures),
      newest_version_(std::move(newest_version)), lag_limit_(lag_limit) {}

SoakWatcher::~SoakWatcher() { stop(); }

void SoakWatcher::start() {
  thread_ = std::thread([this] {
    try {
      run();
    } catch (const std::exception& e) {
      failures_.add(name_ + ": " + e.what());
    }
    std::lock_guard lock(mutex_);
    ended_ = true;
    changed_.notify_all();
  });
}

void SoakWatcher::run() {
  // One thread: the decoder's parallelism would only fight the 47 other watchers for 2 cores.
  FrameDecoder decoder(session_.mesh.rest_positions, 1);
  Reconnect no_reconnect;
  no_reconnect.enabled = false;
  std::uint64_t after = 0;  // the newest version received: where a resumed stream starts
  for (bool resumed = false;; resumed = true) {
    std::unique_ptr<Watcher> watcher;
    {
      std::lock_guard lock(mutex_);
      if (stopping_) return;
      watcher = client_.watch(session_.session_id, session_.viewer_token, after, no_reconnect);
      current_ = watcher.get();
    }
    const auto opened = Clock::now();
    const std::uint64_t resumed_after = resumed ? after : 0;
    std::uint64_t stream_newest = 0;
    bool stream_any = false, deliberate = false;
    while (std::optional<v1::Frame> frame = watcher->read()) {
      if (!take(*frame, decoder, resumed_after, stream_newest, stream_any, opened)) {
        deliberate = true;
        watcher->cancel();
        break;
      }
    }
    const grpc::Status status = watcher->finish();
    bool stopping;
    {
      std::lock_guard lock(mutex_);
      current_ = nullptr;  // before the Watcher goes: stop() must not cancel a dead one
      stopping = stopping_;
      after = stats_.newest_version;
      if (deliberate) ++stats_.reconnects;
    }
    // Ours to end: a cancel, for a resume or for the end of the run.
    if (status.error_code() == grpc::StatusCode::CANCELLED && (deliberate || stopping)) {
      if (deliberate) continue;
      return;
    }
    failures_.add(name_ + ": the Watch stream ended with " + status_code_name(status.error_code()) + ": " +
                  status.error_message());
    return;
  }
}

bool SoakWatcher::take(const v1::Frame& f, FrameDecoder& decoder, std::uint64_t resumed_after,
                       std::uint64_t& stream_newest, bool& stream_any, Clock::time_point opened) {
  const bool keyframe = !f.chunks().empty() && f.keyframe_version() == f.version();
  if (stream_any && f.version() < stream_newest)
    failures_.add(name_ + ": frame version went backwards on a Watch stream, " + std::to_string(stream_newest) + " then " +
                  std::to_string(f.version()));
  if (resumed_after != 0 && !keyframe && f.version() <= resumed_after)
    failures_.add(name_ + ": resumed after version " + std::to_string(resumed_after) + " but got frame " +
                  std::to_string(f.version()) + " (not a keyframe) again");
  stream_any = true;
  stream_newest = std::max(stream_newest, f.version());
  try {
    decoder.decode(f);
  } catch (const std::exception& e) {
    failures_.add(name_ + ": frame " + std::to_string(f.version()) + " does not decode: " + e.what());
  }
  const std::uint64_t driver_pose = pose_in_changes(f, driver_name_);
  {
    std::lock_guard lock(mutex_);
    ++stats_.frames;
    if (f.version() > stats_.newest_version) {
      // Versions between the newest one and this were never received (a
      // keyframe sent first is received, so not counted as skipped).
      if (stats_.frames > 1) stats_.skipped += f.version() - stats_.newest_version - 1;
      stats_.newest_version = f.version();
      stats_.newest_driver_pose = driver_pose;
    }
    changed_.notify_all();
  }
  // A slow reader must still read recent frames: how far behind the driver is this one?
  if (kind_ == WatcherKind::kSlow && newest_version_ && !delay_ended_) {
    const std::uint64_t newest = newest_version_();
    const std::uint64_t lag = newest > f.version() ? newest - f.version() : 0;
    bool over = false;
    {
      std::lock_guard lock(mutex_);
      over = lag > lag_limit_ && lag > stats_.max_lag;  // reported once per new worst
      stats_.max_lag = std::max(stats_.max_lag, lag);
    }
    if (over)
      failures_.add(name_ + ": read version " + std::to_string(f.version()) + " when the driver had seen " +
                    std::to_string(newest) + " (" + std::to_string(lag) + " behind, over " + std::to_string(lag_limit_) + ")");
  }
  // The workload: a slow reader's delay is what makes the server skip frames for it.
  if (kind_ == WatcherKind::kSlow && !delay_ended_) std::this_thread::sleep_for(slow_delay_);
  return !(kind_ == WatcherKind::kReconnecting && Clock::now() - opened >= reconnect_every_);
}

bool SoakWatcher::wait_for_version(std::uint64_t version, Clock::time_point deadline) {
  std::unique_lock lock(mutex_);
  changed_.wait_until(lock, deadline, [&] { return ended_ || stats_.newest_version >= version; });
  return stats_.newest_version >= version;
}

void SoakWatcher::stop() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    if (current_) current_->cancel();
  }
  if (thread_.joinable()) thread_.join();
}

WatcherStats SoakWatcher::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

}  // namespace filigree::soak
