#pragma once
// One pool of threads for every session's frame work (compute, chunk
// encoding), sized to the machine, fair between sessions: each session posts
// to a Lane of its own, and the workers take one task at a time from the
// lanes in turn, so 16 busy sessions share 2 cores without 16 threads
// fighting over them and none waits behind another's whole frame. Tasks of
// one lane may run at the same time (a frame's chunks do).

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

namespace filigree::server {

class FrameScheduler {
 public:
  class Lane;

  // `threads` workers; 0: one per core.
  explicit FrameScheduler(unsigned threads = 0);
  // Runs what is queued, then joins the workers.
  ~FrameScheduler();
  FrameScheduler(const FrameScheduler&) = delete;
  FrameScheduler& operator=(const FrameScheduler&) = delete;

  std::shared_ptr<Lane> lane();
  // Queues `task` on `lane`; tasks must not throw (they catch what they can fail at).
  void post(Lane& lane, std::function<void()> task);
  // Waits until `lane` has nothing queued or running. Not from a task of that lane.
  void drain(Lane& lane);

  unsigned threads() const { return static_cast<unsigned>(workers_.size()); }
  // Lanes with work queued or running now: how many sessions share the cores.
  std::size_t busy_lanes() const;

 private:
  void work();

  mutable std::mutex mutex_;
  std::condition_variable wake_, idle_;
  std::deque<Lane*> ready_;  // lanes with queued tasks, in turn
  std::size_t busy_ = 0;
  bool stopping_ = false;
  std::vector<std::thread> workers_;
};

class FrameScheduler::Lane {
 private:
  friend class FrameScheduler;
  std::deque<std::function<void()>> queue_;
  std::size_t running_ = 0;
  bool in_ready_ = false;
};

}  // namespace filigree::server
