#include "geometry/ring_weights.h"

#include <cmath>

#include "geometry/triangle_geometry.h"

namespace filigree {
namespace {

// Weights below this (relative to the largest) mark an obtuse/degenerate fan.
constexpr double kMinRelativeWeight = 1e-3;

bool normalise(std::vector<double>& w) {
  double sum = 0.0, largest = 0.0;
  for (double x : w) {
    if (!std::isfinite(x) || x <= 0.0) return false;
    sum += x;
    largest = std::max(largest, x);
  }
  if (!(sum > 0.0) || !std::isfinite(sum)) return false;
  for (double x : w)
    if (x < kMinRelativeWeight * largest) return false;
  for (double& x : w) x /= sum;
  return true;
}

}  // namespace

std::vector<double> ring_weights(const Vec3& center, std::span<const Index> ring, std::span<const Vec3> positions,
                                 bool closed) {
  const std::size_t k = ring.size();
  const std::size_t fans = closed ? k : k - 1;
  auto at = [&](std::size_t i) -> const Vec3& { return positions[ring[i % k]]; };

  std::vector<double> w(k, 0.0);
  for (std::size_t f = 0; f < fans; ++f) {
    // Fan triangle (center, ring[f], ring[f+1]): its angle at ring[f+1] weighs
    // spoke f, its angle at ring[f] weighs spoke f+1.
    w[f] += cotangent_at(at(f + 1), center, at(f));
    w[(f + 1) % k] += cotangent_at(at(f), center, at(f + 1));
  }
  if (normalise(w)) return w;

  // Mean-value weights: (tan(α_{k-1}/2) + tan(α_k/2)) / |x_k − center|.
  std::fill(w.begin(), w.end(), 0.0);
  for (std::size_t f = 0; f < fans; ++f) {
    const double half_tan = std::tan(0.5 * angle_at(center, at(f), at(f + 1)));
    w[f] += half_tan;
    w[(f + 1) % k] += half_tan;
  }
  for (std::size_t i = 0; i < k; ++i) w[i] /= std::max((at(i) - center).norm(), 1e-300);
  if (normalise(w)) return w;

  return std::vector<double>(k, 1.0 / static_cast<double>(k));
}

}  // namespace filigree
