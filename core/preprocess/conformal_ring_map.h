#pragma once
// Flattening of a vertex's 1-ring with the conformal polar map of MAPS
// (thesis §3.1.2, Lee et al. 1998).

#include <span>
#include <vector>

#include <Eigen/Core>

#include "mesh/tri_mesh.h"

namespace filigree {

using Vec2 = Eigen::Vector2d;

// Maps ring vertex k to r_k^a · exp(i·a·θ_k), with the centre at the origin,
// θ_k the accumulated 3D angle between consecutive spokes and a = 2π/Θ for a
// closed ring, π/Θ for an open (boundary) one, so the ring becomes a star-shaped
// counter-clockwise polygon around the origin (open: in the upper half-plane,
// ring[0] on +x, ring[K−1] on −x). Radii are divided by their mean first so the
// map does not depend on the mesh's units. Returns an empty vector when the fan
// is degenerate (a zero-length spoke or a total angle of ~0).
std::vector<Vec2> conformal_ring_map(const Vec3& center, std::span<const Index> ring,
                                     std::span<const Vec3> positions, bool closed);
// The same into `uv` (reusing its storage); false, and `uv` empty, when the
// fan is degenerate.
bool conformal_ring_map(const Vec3& center, std::span<const Index> ring, std::span<const Vec3> positions, bool closed,
                        std::vector<Vec2>& uv);

}  // namespace filigree
