#include "preprocess/conformal_ring_map.h"

#include <cmath>
#include <numbers>

#include "geometry/triangle_geometry.h"

namespace filigree {

std::vector<Vec2> conformal_ring_map(const Vec3& center, std::span<const Index> ring,
                                     std::span<const Vec3> positions, bool closed) {
  const std::size_t k = ring.size();
  std::vector<double> theta(k, 0.0), radius(k);
  double mean_radius = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    radius[i] = (positions[ring[i]] - center).norm();
    if (!(radius[i] > 0.0)) return {};
    mean_radius += radius[i] / static_cast<double>(k);
  }
  const std::size_t spans = closed ? k : k - 1;
  double total = 0.0;
  for (std::size_t i = 0; i < spans; ++i) {
    if (i > 0) theta[i] = total;
    total += angle_at(center, positions[ring[i]], positions[ring[(i + 1) % k]]);
  }
  if (!(total > 1e-9)) return {};
  const double a = (closed ? 2.0 : 1.0) * std::numbers::pi / total;

  std::vector<Vec2> uv(k);
  for (std::size_t i = 0; i < k; ++i) {
    const double r = std::pow(radius[i] / mean_radius, a);
    uv[i] = Vec2(r * std::cos(a * theta[i]), r * std::sin(a * theta[i]));
  }
  if (!closed) uv[k - 1] = Vec2(-std::pow(radius[k - 1] / mean_radius, a), 0.0);  // exactly on −x
  return uv;
}

}  // namespace filigree
