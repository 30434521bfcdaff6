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
  // Half-weights bucketed by their row (a counting sort, O(n)), then each
  // short row sorted by column and its repeats summed: a global sort of all
  // half-weights took seconds and 24 bytes each at a million vertices.
  const std::size_t n = mesh.positions.size();
  std::vector<Index> start(n + 1, 0);
  for (const Triangle& f : mesh.faces)
    for (Index v : f) start[v + 1] += 2;  // each corner's vertex gets a half-weight from both other corners' angles
  for (std::size_t i = 0; i < n; ++i) start[i + 1] += start[i];
  struct Half {
    Index to;
    double w;
  };
  std::vector<Half> halves(start[n]);
  std::vector<Index> fill(start.begin(), start.end() - 1);
  for (const Triangle& f : mesh.faces) {
    for (int c = 0; c < 3; ++c) {
      // The angle at corner c weighs the opposite edge (f[c+1], f[c+2]).
      const Index a = f[c], b = f[(c + 1) % 3], d = f[(c + 2) % 3];
      const double half_cot = 0.5 * cotangent_at(mesh.positions[a], mesh.positions[b], mesh.positions[d]);
      halves[fill[b]++] = {d, half_cot};
      halves[fill[d]++] = {b, half_cot};
    }
  }
  fill = {};
  CotangentLaplacian L;
  L.offsets.assign(n + 1, 0);
  L.neighbors.reserve(halves.size() / 2);
  L.weights.reserve(halves.size() / 2);
  for (std::size_t i = 0; i < n; ++i) {
    Half* first = halves.data() + start[i];
    Half* last = halves.data() + start[i + 1];
    // Insertion sort: rows are short, and it is stable, so repeats are
    // summed in face order.
    for (Half* h = first + 1; h < last; ++h)
      for (Half* g = h; g > first && g[-1].to > g->to; --g) std::swap(g[-1], g[0]);
    for (Half* h = first; h != last;) {
      double w = 0.0;
      const Index to = h->to;
      for (; h != last && h->to == to; ++h) w += h->w;
      L.neighbors.push_back(to);
      L.weights.push_back(std::clamp(w, CotangentLaplacian::kMinWeight, CotangentLaplacian::kMaxWeight));
    }
    L.offsets[i + 1] = static_cast<Index>(L.neighbors.size());
  }
  return L;
}

}  // namespace filigree
