#pragma once
// Which clip time each sample of a PlayClip stream showed.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <mutex>
#include <utility>

namespace filigree::server {

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

}  // namespace filigree::server
