#include "bench/streaming_bound.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>
#include <vector>

namespace filigree::bench {

double streaming_copy_ms(std::size_t bytes, int threads, int repeats) {
  const std::size_t half = std::max<std::size_t>(bytes / 2, 64);
  std::vector<char> src(half, 1), dst(half, 0);  // written once: every page is faulted in
  const std::size_t t = static_cast<std::size_t>(std::max(1, threads));
  double best = 1e300;
  for (int r = 0; r < repeats; ++r) {
    const auto start = std::chrono::steady_clock::now();
    {
      std::vector<std::jthread> team;
      for (std::size_t k = 1; k < t; ++k)
        team.emplace_back([&, k] { std::memcpy(dst.data() + half * k / t, src.data() + half * k / t, half * (k + 1) / t - half * k / t); });
      std::memcpy(dst.data(), src.data(), half / t);
    }
    best = std::min(best, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    src[static_cast<std::size_t>(r) % half] ^= dst[static_cast<std::size_t>(r * 7) % half];  // keep the copies observable
  }
  return best;
}

}  // namespace filigree::bench
