#include "mesh/tri_mesh.h"

namespace filigree {

double bounding_box_diagonal(std::span<const Vec3> positions) {
  if (positions.empty()) return 0.0;
  Vec3 lo = positions.front(), hi = positions.front();
  for (const Vec3& p : positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).norm();
}

std::vector<Vec3> points_from_xyz(const std::vector<float>& xyz) {
  std::vector<Vec3> out(xyz.size() / 3);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = Vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
  return out;
}

}  // namespace filigree
