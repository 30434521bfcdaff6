#pragma once
// Quaternion barycentric interpolation of base rotations to any vertex
// through its MAPS coordinates (thesis §3.1.2).

#include <array>

#include <Eigen/Geometry>

#include "mesh/tri_mesh.h"

namespace filigree {

// Σ b_c·q_c over the three corners, with each q_c first flipped into the
// hemisphere of the corner with the largest weight (q and −q are the same
// rotation; mixing hemispheres would cancel them out), then normalised.
// Falls back to the largest-weight corner's rotation if the sum vanishes.
Eigen::Quaterniond interpolate_rotation(const std::array<Eigen::Quaterniond, 3>& q, const Vec3& bary);

}  // namespace filigree
