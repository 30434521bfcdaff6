#pragma once
// A local frame attached to a vertex's 1-ring, so that a removed vertex's
// offset from its ring can be stored rotation- and scale-invariantly and put
// back after the ring moves (thesis eq. 3.10 with the local frame of §3.1.2).

#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "mesh/tri_mesh.h"

namespace filigree {

struct RingFrame {
  Vec3 center;           // Σ w_k x_k, the weighted ring average
  Eigen::Matrix3d axes;  // orthonormal columns: tangent, bitangent, normal
  double scale = 1.0;    // mean distance of the ring vertices to `center`

  // Offset of p from the centre in frame coordinates, divided by scale.
  Vec3 to_local(const Vec3& p) const;
  Vec3 from_local(const Vec3& local) const;
};

// Frame of the ring: the centre is the weighted average Σ w_k x_k / Σ w_k,
// the normal the ring polygon's vector area about the centre (open rings are
// not closed), the tangent the direction to ring[0] projected into the
// tangent plane. Degenerate rings get an arbitrary but deterministic
// orthonormal basis and scale 1, never NaN.
// Weights are relative (the centre is Σ w x / Σ w): the hierarchy's 16-bit
// fixed-point weights sum to 65535 only up to rounding, and without the
// division the centre would drift by (Σ w − 1)·x, growing with the
// distance from the coordinate origin.
RingFrame ring_frame(std::span<const Index> ring, std::span<const double> weights,
                     std::span<const Vec3> positions, bool closed);
RingFrame ring_frame(std::span<const Index> ring, std::span<const std::uint16_t> weights,
                     std::span<const Vec3> positions, bool closed);

}  // namespace filigree
