#pragma once
// A pose: positions for the base mesh's vertices, in base order (the order of
// Hierarchy::base_vertices and of `filigree export-base`).

#include <stdexcept>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct Pose {
  std::vector<Vec3> positions;
};

// A pose that cannot be used: wrong length, NaN/Inf; what() says which.
struct PoseError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// Throws PoseError unless `pose` has exactly `base_vertex_count` finite positions.
void validate_pose(const Pose& pose, std::size_t base_vertex_count);

}  // namespace filigree
