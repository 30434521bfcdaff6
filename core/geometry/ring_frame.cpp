#include "geometry/ring_frame.h"

#include <cmath>

#include <Eigen/Geometry>

namespace filigree {

Vec3 RingFrame::to_local(const Vec3& p) const { return axes.transpose() * (p - center) / scale; }

Vec3 RingFrame::from_local(const Vec3& local) const { return center + scale * (axes * local); }

namespace {

template <class W>
RingFrame frame_of(std::span<const Index> ring, std::span<const W> weights, std::span<const Vec3> positions, bool closed) {
  const std::size_t k = ring.size();
  RingFrame frame;
  frame.center = Vec3::Zero();
  double sum = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    frame.center += static_cast<double>(weights[i]) * positions[ring[i]];
    sum += static_cast<double>(weights[i]);
  }
  // Weights are positive (ring_weights.h); a zero sum only from a bad caller.
  if (sum > 0.0) frame.center /= sum;

  Vec3 normal = Vec3::Zero();
  double radius = 0.0;
  for (std::size_t i = 0; i < k; ++i) {
    const Vec3 a = positions[ring[i]] - frame.center;
    radius += a.norm();
    if (closed || i + 1 < k) normal += a.cross(positions[ring[(i + 1) % k]] - frame.center);
  }
  radius /= static_cast<double>(k);
  frame.scale = radius > 1e-300 && std::isfinite(radius) ? radius : 1.0;

  const double nn = normal.norm();
  normal = nn > 1e-300 ? Vec3(normal / nn) : Vec3::UnitZ();
  Vec3 tangent = positions[ring[0]] - frame.center;
  tangent -= normal * normal.dot(tangent);
  if (tangent.norm() <= 1e-12 * frame.scale) {
    // ring[0] sits on the normal axis: take any direction orthogonal to it.
    tangent = std::abs(normal.x()) < 0.9 ? Vec3::UnitX() : Vec3::UnitY();
    tangent -= normal * normal.dot(tangent);
  }
  tangent.normalize();
  frame.axes.col(0) = tangent;
  frame.axes.col(1) = normal.cross(tangent);
  frame.axes.col(2) = normal;
  return frame;
}

}  // namespace

RingFrame ring_frame(std::span<const Index> ring, std::span<const double> weights,
                     std::span<const Vec3> positions, bool closed) {
  return frame_of(ring, weights, positions, closed);
}

RingFrame ring_frame(std::span<const Index> ring, std::span<const std::uint16_t> weights,
                     std::span<const Vec3> positions, bool closed) {
  return frame_of(ring, weights, positions, closed);
}

}  // namespace filigree
