#include "server/frame_scheduler.h"

#include <algorithm>

namespace filigree::server {

FrameScheduler::FrameScheduler(unsigned threads) {
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  for (unsigned t = 0; t < threads; ++t) workers_.emplace_back([this] { work(); });
}

FrameScheduler::~FrameScheduler() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  wake_.notify_all();
  for (std::thread& t : workers_) t.join();
}

std::shared_ptr<FrameScheduler::Lane> FrameScheduler::lane() { return std::make_shared<Lane>(); }

void FrameScheduler::post(Lane& lane, std::function<void()> task) {
  {
    std::lock_guard lock(mutex_);
    if (lane.queue_.empty() && lane.running_ == 0) ++busy_;
    lane.queue_.push_back(std::move(task));
    if (!lane.in_ready_) {
      lane.in_ready_ = true;
      ready_.push_back(&lane);
    }
  }
  wake_.notify_one();
}

void FrameScheduler::drain(Lane& lane) {
  std::unique_lock lock(mutex_);
  idle_.wait(lock, [&] { return lane.queue_.empty() && lane.running_ == 0; });
}

std::size_t FrameScheduler::busy_lanes() const {
  std::lock_guard lock(mutex_);
  return busy_;
}

void FrameScheduler::work() {
  std::unique_lock lock(mutex_);
  while (true) {
    wake_.wait(lock, [&] { return stopping_ || !ready_.empty(); });
    if (ready_.empty()) return;  // stopping, nothing left
    // Round robin: one task from the lane at the front, which goes to the
    // back if it has more.
    Lane& lane = *ready_.front();
    ready_.pop_front();
    std::function<void()> task = std::move(lane.queue_.front());
    lane.queue_.pop_front();
    ++lane.running_;
    if (lane.queue_.empty()) {
      lane.in_ready_ = false;
    } else {
      ready_.push_back(&lane);
    }
    lock.unlock();
    task();
    task = nullptr;  // what it captured is released outside the lock too
    lock.lock();
    --lane.running_;
    if (lane.queue_.empty() && lane.running_ == 0) {
      --busy_;
      idle_.notify_all();
    }
  }
}

}  // namespace filigree::server
