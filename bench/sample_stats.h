#pragma once
// Order statistics of timed samples, shared by the benchmarks.

#include <algorithm>
#include <cstddef>
#include <vector>

namespace filigree::bench {

// The sample at rank p·size (p in [0, 1]) of the sorted samples; 0 for none.
inline double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

// The median (the mean of the two middle samples for an even count); 0 for none.
inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace filigree::bench
