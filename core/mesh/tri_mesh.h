#pragma once
// The plain triangle mesh every module exchanges: positions and faces, nothing else.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace filigree {

using Vec3 = Eigen::Vector3d;
using Index = std::uint32_t;
using Triangle = std::array<Index, 3>;

// An indexed triangle mesh. Faces are counter-clockwise seen from outside;
// indices refer to `positions`. No invariant is enforced here: see
// mesh_validation.h for what a mesh must satisfy before preprocessing.
struct TriMesh {
  std::vector<Vec3> positions;
  std::vector<Triangle> faces;

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t face_count() const { return faces.size(); }
};

// Length of the diagonal of the axis-aligned bounding box (0 for an empty mesh).
double bounding_box_diagonal(std::span<const Vec3> positions);

// Points from packed x y z floats, the form of the wire and the client
// library (a trailing partial point is ignored).
std::vector<Vec3> points_from_xyz(const std::vector<float>& xyz);

}  // namespace filigree
