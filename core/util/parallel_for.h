#pragma once
// A minimal deterministic parallel loop: [0, n) is split into contiguous
// chunks, so each index is handled by exactly one call whatever the
// scheduling, and results written per index do not depend on thread timing.

#include <algorithm>
#include <cstddef>
#include <exception>
#include <thread>
#include <vector>

namespace filigree {

// Runs fn(begin, end) over [0, n) split into `parts` (≥ 1) contiguous ranges,
// each on a thread of its own (the calling one for a single part); rethrows
// the first range's exception, if any, once all have ended.
template <class Fn>
void parallel_ranges(std::size_t n, std::size_t parts, Fn&& fn) {
  if (parts <= 1) {
    fn(std::size_t{0}, n);
    return;
  }
  std::vector<std::exception_ptr> errors(parts);
  {
    std::vector<std::jthread> pool;
    pool.reserve(parts);
    for (std::size_t p = 0; p < parts; ++p) {
      pool.emplace_back([&, p] {
        try {
          fn(n * p / parts, n * (p + 1) / parts);
        } catch (...) {
          errors[p] = std::current_exception();
        }
      });
    }
  }
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

// fn(i) for every i in [0, n), on up to `threads` threads (at least 1024
// indices each).
template <class Fn>
void parallel_for(std::size_t n, int threads, Fn&& fn) {
  const std::size_t t = std::clamp<std::size_t>(threads > 0 ? threads : 1, 1, std::max<std::size_t>(n / 1024, 1));
  parallel_ranges(n, t, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) fn(i);
  });
}

}  // namespace filigree
