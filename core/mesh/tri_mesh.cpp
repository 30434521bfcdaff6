#include "mesh/tri_mesh.h"

namespace filigree {

double bounding_box_diagonal(const std::vector<Vec3>& positions) {
  if (positions.empty()) return 0.0;
  Vec3 lo = positions.front(), hi = positions.front();
  for (const Vec3& p : positions) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  return (hi - lo).norm();
}

}  // namespace filigree
