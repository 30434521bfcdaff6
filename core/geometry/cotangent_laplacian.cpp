#include "geometry/cotangent_laplacian.h"

#include <algorithm>

#include "geometry/triangle_geometry.h"

namespace filigree {

std::vector<Vec3> CotangentLaplacian::apply(const std::vector<Vec3>& x) const {
  std::vector<Vec3> out(vertex_count(), Vec3::Zero());
  for (std::size_t i = 0; i < vertex_count(); ++i) {
    Vec3 acc = Vec3::Zero();
    for (Index k = offsets[i]; k < offsets[i + 1]; ++k) acc += weights[k] * (x[i] - x[neighbors[k]]);
    out[i] = acc;
  }
  return out;
}

CotangentLaplacian cotangent_laplacian(const TriMesh& mesh) {
  struct HalfWeight {
    Index from, to;
    double w;
  };
  std::vector<HalfWeight> halves;
  halves.reserve(mesh.faces.size() * 6);
  for (const Triangle& f : mesh.faces) {
    for (int c = 0; c < 3; ++c) {
      // The angle at corner c weighs the opposite edge (f[c+1], f[c+2]).
      const Index a = f[c], b = f[(c + 1) % 3], d = f[(c + 2) % 3];
      const double half_cot = 0.5 * cotangent_at(mesh.positions[a], mesh.positions[b], mesh.positions[d]);
      halves.push_back({b, d, half_cot});
      halves.push_back({d, b, half_cot});
    }
  }
  std::sort(halves.begin(), halves.end(),
            [](const HalfWeight& p, const HalfWeight& q) { return p.from != q.from ? p.from < q.from : p.to < q.to; });

  CotangentLaplacian L;
  L.offsets.assign(mesh.positions.size() + 1, 0);
  for (std::size_t k = 0; k < halves.size();) {
    std::size_t e = k;
    double w = 0.0;
    while (e < halves.size() && halves[e].from == halves[k].from && halves[e].to == halves[k].to) w += halves[e++].w;
    L.neighbors.push_back(halves[k].to);
    L.weights.push_back(std::clamp(w, CotangentLaplacian::kMinWeight, CotangentLaplacian::kMaxWeight));
    ++L.offsets[halves[k].from + 1];
    k = e;
  }
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) L.offsets[i + 1] += L.offsets[i];
  return L;
}

}  // namespace filigree
