#include "preprocess/mean_curvature.h"

#include "geometry/cotangent_laplacian.h"
#include "geometry/triangle_geometry.h"

namespace filigree {

std::vector<double> mean_curvature(const TriMesh& mesh, const CotangentLaplacian& laplacian,
                                   const std::vector<bool>& is_boundary) {
  const std::size_t n = mesh.positions.size();
  std::vector<double> area(n, 0.0);
  for (const Triangle& f : mesh.faces) {
    const double a = triangle_area(mesh.positions[f[0]], mesh.positions[f[1]], mesh.positions[f[2]]) / 3.0;
    for (Index v : f) area[v] += a;
  }
  const std::vector<Vec3> delta = laplacian.apply(mesh.positions);
  std::vector<double> h(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    if (!is_boundary[i] && area[i] > 0.0) h[i] = delta[i].norm() / (2.0 * area[i]);
  }
  return h;
}

}  // namespace filigree
