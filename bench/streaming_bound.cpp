#include "bench/streaming_bound.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

namespace filigree::bench {

StreamingCopy::StreamingCopy(std::size_t bytes)
    : src_(std::max<std::size_t>(bytes / 2, 64), 1), dst_(src_.size(), 0) {}  // written once: every page is faulted in

double StreamingCopy::run_ms(int threads) {
  const std::size_t half = src_.size();
  const std::size_t t = static_cast<std::size_t>(std::max(1, threads));
  const auto start = std::chrono::steady_clock::now();
  {
    std::vector<std::jthread> team;
    for (std::size_t k = 1; k < t; ++k)
      team.emplace_back([&, k] { std::memcpy(dst_.data() + half * k / t, src_.data() + half * k / t, half * (k + 1) / t - half * k / t); });
    std::memcpy(dst_.data(), src_.data(), half / t);
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  src_[runs_ % half] ^= dst_[(runs_ * 7) % half];  // keep the copies observable
  ++runs_;
  return ms;
}

}  // namespace filigree::bench
