#pragma once
// A minimal deterministic parallel loop: [0, n) is split into `threads`
// contiguous chunks, so each index is handled by exactly one call whatever the
// scheduling, and results written per index do not depend on thread timing.

#include <algorithm>
#include <cstddef>
#include <thread>
#include <vector>

namespace filigree {

template <class Fn>
void parallel_for(std::size_t n, int threads, Fn&& fn) {
  const std::size_t t = std::clamp<std::size_t>(threads > 0 ? threads : 1, 1, std::max<std::size_t>(n / 1024, 1));
  if (t == 1) {
    for (std::size_t i = 0; i < n; ++i) fn(i);
    return;
  }
  std::vector<std::jthread> pool;
  pool.reserve(t);
  for (std::size_t k = 0; k < t; ++k) {
    pool.emplace_back([&, k] {
      const std::size_t begin = n * k / t, end = n * (k + 1) / t;
      for (std::size_t i = begin; i < end; ++i) fn(i);
    });
  }
}

}  // namespace filigree
