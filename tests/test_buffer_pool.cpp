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

TEST(BufferPool, KeepsAtMostItsBoundAndIgnoresEmptyBuffers) {
  BufferPool<double> pool(1);
  pool.give(pool.take(8));
  pool.give(pool.take(8));  // the same one again
  std::vector<double> a = pool.take(8), b = pool.take(8);
  pool.give(std::move(a));
  pool.give(std::move(b));  // over the bound: freed
  EXPECT_EQ(pool.free_buffers(), 1u);
  pool.give(std::vector<double>{});
  EXPECT_EQ(pool.free_buffers(), 1u);
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
  EXPECT_LE(pool.free_buffers(), 4u);
}

}  // namespace
}  // namespace filigree
