#include "preprocess/conformal_ring_map.h"

#include <cmath>
#include <numbers>

#include "geometry/triangle_geometry.h"

namespace filigree {

std::vector<Vec2> conformal_ring_map(const Vec3& center, std::span<const Index> ring,
                                     std::span<const Vec3> positions, bool closed) {
  std::vector<Vec2> uv;
  conformal_ring_map(center, ring, positions, closed, uv);
  return uv;
}

bool conformal_ring_map(const Vec3& center, std::span<const Index> ring, std::span<const Vec3> positions, bool closed,
                        std::vector<Vec2>& uv) {
  const std::size_t k = ring.size();
  // uv holds (radius, θ) until the last loop maps them: no scratch arrays.
  uv.assign(k, Vec2::Zero());
  double mean_radius = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    const double radius = (positions[ring[i]] - center).norm();
    if (!(radius > 0.0)) {
      uv.clear();
      return false;
    }
    uv[i].x() = radius;
    mean_radius += radius / static_cast<double>(k);
  }
  const std::size_t spans = closed ? k : k - 1;
  double total = 0.0;
  for (std::size_t i = 0; i < spans; ++i) {
    if (i > 0) uv[i].y() = total;
    total += angle_at(center, positions[ring[i]], positions[ring[(i + 1) % k]]);
  }
  if (!(total > 1e-9)) {
    uv.clear();
    return false;
  }
  const double a = (closed ? 2.0 : 1.0) * std::numbers::pi / total;
  const double last_radius = uv[k - 1].x();
  for (std::size_t i = 0; i < k; ++i) {
    const double r = std::pow(uv[i].x() / mean_radius, a), theta = uv[i].y();
    uv[i] = Vec2(r * std::cos(a * theta), r * std::sin(a * theta));
  }
  if (!closed) uv[k - 1] = Vec2(-std::pow(last_radius / mean_radius, a), 0.0);  // exactly on −x
  return true;
}

}  // namespace filigree
