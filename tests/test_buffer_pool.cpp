// BufferPool: scratch that owners take and give back (util/buffer_pool.h).

#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "util/buffer_pool.h"

namespace filigree {
namespace {

TEST(BufferPool, AGivenBufferIsTakenAgainWithoutReallocation) {
  BufferPool<float> pool(2);
  std::vector<float> a = pool.take(1000);
  ASSERT_EQ(a.size(), 1000u);
  const float* storage = a.data();
  pool.give(std::move(a));
  EXPECT_EQ(pool.free_buffers(), 1u);
  const std::vector<float> b = pool.take(600);  // smaller: the same storage, resized
  EXPECT_EQ(b.data(), storage);
  EXPECT_EQ(b.size(), 600u);
  EXPECT_EQ(pool.free_buffers(), 0u);
}

TEST(BufferPool, TakesTheSmallestBufferThatFitsAndNeverOneTooSmall) {
  BufferPool<int> pool(4);
  std::vector<int> small = pool.take(10), middle = pool.take(100), large = pool.take(1000);
  const int* middle_storage = middle.data();
  pool.give(std::move(large));
  pool.give(std::move(small));
  pool.give(std::move(middle));
  const std::vector<int> got = pool.take(50);
  EXPECT_EQ(got.data(), middle_storage) << "the 100 fits 50 best; 10 is too small, 1000 wasteful";
  const std::vector<int> huge = pool.take(5000);  // none fits: a new one
  EXPECT_EQ(huge.size(), 5000u);
  EXPECT_EQ(pool.free_buffers(), 2u);
}

TEST(BufferPool, KeepsItsMinimumAndIgnoresEmptyBuffers) {
  BufferPool<double> pool(1);
  pool.give(pool.take(8));
  pool.give(pool.take(8));  // the same one again
  EXPECT_EQ(pool.free_buffers(), 1u);
  pool.give(std::vector<double>{});
  EXPECT_EQ(pool.free_buffers(), 1u);
}

TEST(BufferPool, KeepsAsManyAsWereBusyAtOnceSoABusySteadyStateAllocatesNothing) {
  // Eight owners (sessions of one mesh) against a minimum of one: every
  // buffer they held at once comes back for the next round.
  BufferPool<double> pool(1);
  for (int round = 0; round < 3 * static_cast<int>(BufferPool<double>::kEpochTakes); ++round) {
    std::vector<std::vector<double>> held;
    for (int owner = 0; owner < 8; ++owner) held.push_back(pool.take(1000));
    EXPECT_EQ(pool.free_buffers(), 0u) << "round " << round << ": the eight took every free buffer";
    for (auto& buffer : held) pool.give(std::move(buffer));
    ASSERT_EQ(pool.free_buffers(), 8u) << "round " << round;
  }
}

TEST(BufferPool, BuffersBeyondDemandGoWhenDemandFalls) {
  BufferPool<double> pool(2);
  std::vector<std::vector<double>> held;
  for (int owner = 0; owner < 8; ++owner) held.push_back(pool.take(100));
  for (auto& buffer : held) pool.give(std::move(buffer));
  EXPECT_EQ(pool.free_buffers(), 8u);
  // One owner from now on: within two epochs of takes, only the minimum stays.
  for (std::size_t i = 0; i < 2 * BufferPool<double>::kEpochTakes; ++i) pool.give(pool.take(100));
  EXPECT_EQ(pool.free_buffers(), 2u);
  // A buffer given back without a take (not the pool's) is kept only within bounds too.
  pool.give(std::vector<double>(100));
  pool.give(std::vector<double>(100));
  EXPECT_EQ(pool.free_buffers(), 2u);
}

TEST(BufferPool, AnIdlePoolDropsWhatItKeptForABurstAndABusyOneKeepsIt) {
  BufferPool<double> pool(2);
  auto burst = [&pool] {
    std::vector<std::vector<double>> held;
    for (int owner = 0; owner < 8; ++owner) held.push_back(pool.take(100));
    for (auto& buffer : held) pool.give(std::move(buffer));
  };
  burst();
  EXPECT_EQ(pool.trim_if_idle(), 0u) << "takes since the last call: busy";
  EXPECT_EQ(pool.free_buffers(), 8u);
  burst();
  EXPECT_EQ(pool.trim_if_idle(), 0u);
  EXPECT_EQ(pool.free_buffers(), 8u);
  // No take since the last call: idle, back to the minimum.
  EXPECT_EQ(pool.trim_if_idle(), 6u);
  EXPECT_EQ(pool.free_buffers(), 2u);
  // A buffer still out is not counted as free, and comes back within bounds.
  std::vector<double> out = pool.take(100);
  EXPECT_EQ(pool.trim_if_idle(), 0u);
  EXPECT_EQ(pool.trim_if_idle(), 0u) << "nothing beyond the minimum";
  pool.give(std::move(out));
  EXPECT_EQ(pool.free_buffers(), 2u);
}

TEST(BufferPool, ConcurrentOwnersEachGetTheirOwnBuffer) {
  BufferPool<int> pool(4);
  std::vector<std::thread> threads;
  std::vector<int> wrong(4, 0);
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&pool, &wrong, t] {
      for (int round = 0; round < 2000; ++round) {
        std::vector<int> buffer = pool.take(64);
        std::fill(buffer.begin(), buffer.end(), t);
        for (int v : buffer) wrong[t] += v != t;  // another owner wrote into it
        pool.give(std::move(buffer));
      }
    });
  for (std::thread& t : threads) t.join();
  for (int t = 0; t < 4; ++t) EXPECT_EQ(wrong[t], 0) << "thread " << t;
  EXPECT_LE(pool.free_buffers(), 4u) << "never more than were in use at once";
}

}  // namespace
}  // namespace filigree
