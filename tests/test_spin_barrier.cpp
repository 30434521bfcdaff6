// SpinBarrier (util/spin_barrier.h): no thread leaves a phase before every
// thread has finished it, and what they wrote is seen after it.

#include <atomic>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "util/spin_barrier.h"

namespace filigree {
namespace {

TEST(SpinBarrier, NoThreadLeavesAPhaseBeforeEveryThreadFinishedIt) {
  constexpr int kThreads = 4, kPhases = 2000;
  SpinBarrier barrier(kThreads);
  // Plain ints written by one thread, read by all after the barrier: the
  // barrier alone must order them.
  std::vector<int> done(kThreads, 0);
  std::atomic<int> early{0};
  std::vector<std::thread> team;
  for (int t = 0; t < kThreads; ++t)
    team.emplace_back([&, t] {
      for (int phase = 1; phase <= kPhases; ++phase) {
        done[t] = phase;
        barrier.arrive_and_wait();
        for (int other = 0; other < kThreads; ++other)
          if (done[other] < phase) early.fetch_add(1);
        barrier.arrive_and_wait();  // nobody starts the next phase while others still read
      }
    });
  for (std::thread& t : team) t.join();
  EXPECT_EQ(early.load(), 0);
}

TEST(SpinBarrier, AThreadThatArrivesLongBeforeTheOthersStillWaitsForThem) {
  // The early thread spins out and sleeps; it must still wake for the late one.
  SpinBarrier barrier(2);
  std::atomic<bool> late_arrived{false}, left_early{false};
  std::thread early([&] {
    barrier.arrive_and_wait();
    if (!late_arrived.load()) left_early = true;
  });
  // The late thread arrives only after doing this much work: longer than the spin.
  volatile double sink = 0.0;
  for (int i = 0; i < 20'000'000; ++i) sink = sink + 1e-9 * i;
  late_arrived = true;
  barrier.arrive_and_wait();
  early.join();
  EXPECT_FALSE(left_early.load());
}

}  // namespace
}  // namespace filigree
