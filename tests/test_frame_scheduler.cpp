// The shared frame scheduler: sessions' lanes take turns, and a lane drains.

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "server/frame_scheduler.h"

namespace filigree::server {
namespace {

// A gate the first task waits at, so the others queue up behind it.
struct Gate {
  std::mutex mutex;
  std::condition_variable cv;
  bool open = false;
  void wait() {
    std::unique_lock lock(mutex);
    cv.wait(lock, [&] { return open; });
  }
  void release() {
    {
      std::lock_guard lock(mutex);
      open = true;
    }
    cv.notify_all();
  }
};

TEST(FrameScheduler, LanesTakeTurnsSoNoSessionWaitsBehindAnothersWholeFrame) {
  FrameScheduler scheduler(1);
  auto a = scheduler.lane(), b = scheduler.lane(), c = scheduler.lane();
  std::mutex mutex;
  std::string order;
  Gate gate, started;
  const auto record = [&](char name) {
    std::lock_guard lock(mutex);
    order += name;
  };
  scheduler.post(*a, [&] {
    started.release();
    gate.wait();
    record('a');
  });
  started.wait();
  // While the first task blocks the only worker: lane a queues 5 more, then b and c 2 each.
  for (int i = 0; i < 5; ++i) scheduler.post(*a, [&] { record('a'); });
  for (int i = 0; i < 2; ++i) scheduler.post(*b, [&] { record('b'); });
  for (int i = 0; i < 2; ++i) scheduler.post(*c, [&] { record('c'); });
  EXPECT_EQ(scheduler.busy_lanes(), 3u);
  gate.release();
  scheduler.drain(*a);
  scheduler.drain(*b);
  scheduler.drain(*c);
  // One task per lane in turn, not a's six first.
  EXPECT_EQ(order, "aabcabcaaa");
  EXPECT_EQ(scheduler.busy_lanes(), 0u);
}

TEST(FrameScheduler, TasksOfOneLaneRunInParallelAndDrainWaitsForAll) {
  FrameScheduler scheduler(2);
  auto lane = scheduler.lane();
  std::atomic<int> done{0};
  Gate gate;
  std::atomic<int> waiting{0};
  // Two tasks that each wait for the other to have started: only possible on two threads at once.
  for (int i = 0; i < 2; ++i)
    scheduler.post(*lane, [&] {
      if (++waiting == 2) gate.release();
      gate.wait();
      ++done;
    });
  scheduler.drain(*lane);
  EXPECT_EQ(done.load(), 2);
}

}  // namespace
}  // namespace filigree::server
