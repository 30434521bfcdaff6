#include "geometry/cotangent_laplacian.h"

#include <algorithm>

#include "geometry/triangle_geometry.h"
#include "util/parallel_for.h"

namespace filigree {

std::vector<Vec3> CotangentLaplacian::apply(std::span<const Vec3> x) const {
  std::vector<Vec3> out(vertex_count(), Vec3::Zero());
  for (std::size_t i = 0; i < vertex_count(); ++i) {
    Vec3 acc = Vec3::Zero();
    for (Index k = offsets[i]; k < offsets[i + 1]; ++k) acc += weights[k] * (x[i] - x[neighbors[k]]);
    out[i] = acc;
  }
  return out;
}

CotangentLaplacian cotangent_laplacian(std::span<const Vec3> positions, std::span<const Triangle> faces, int threads) {
  // Row by row over each vertex's faces (a counting sort of the corners,
  // O(n)), in ascending face order, so that each row sees its half-weights
  // in the order a pass over the faces would give them; each short row is
  // then sorted by column and its repeats summed. A global sort of all
  // half-weights took seconds and 24 bytes each at a million vertices, and
  // bucketing them all first still wrote 16 bytes per half-weight (240 MB
  // of fresh memory at 1.25M vertices); the corner lists are 4 bytes a
  // corner. Each cotangent is computed twice (for the rows of both ends of
  // its edge): a per-face cache of them measured slower (60 MB more fresh
  // memory). 1.25M vertices on this VM: 2.06–2.14 s → 1.33 s, same bits.
  const std::size_t n = positions.size();
  std::vector<Index> first_face(n + 1, 0);
  for (const Triangle& f : faces)
    for (Index v : f) ++first_face[v + 1];
  for (std::size_t i = 0; i < n; ++i) first_face[i + 1] += first_face[i];
  std::vector<Index> faces_of(first_face[n]);
  {
    std::vector<Index> fill(first_face.begin(), first_face.end() - 1);
    for (std::size_t f = 0; f < faces.size(); ++f)
      for (Index v : faces[f]) faces_of[fill[v]++] = static_cast<Index>(f);
  }
  struct Half {
    Index to;
    double w;
  };
  // Rows [begin, end) appended to `out` (offsets relative to its start).
  const auto build_rows = [&](std::size_t begin, std::size_t end, CotangentLaplacian& out) {
    std::vector<Half> row;
    for (std::size_t i = begin; i < end; ++i) {
      row.clear();
      for (Index k = first_face[i]; k < first_face[i + 1]; ++k) {
        if (k > first_face[i] && faces_of[k] == faces_of[k - 1]) continue;  // a face listing i twice, seen once
        const Triangle& f = faces[faces_of[k]];
        for (int c = 0; c < 3; ++c) {
          // The angle at corner c weighs the opposite edge (f[c+1], f[c+2]).
          const Index a = f[c], b = f[(c + 1) % 3], d = f[(c + 2) % 3];
          if (b != i && d != i) continue;
          const double half_cot = 0.5 * cotangent_at(positions[a], positions[b], positions[d]);
          if (b == i) row.push_back({d, half_cot});
          if (d == i) row.push_back({b, half_cot});
        }
      }
      // Stable, so repeats are summed in face order: an insertion sort for
      // the usual short rows, a merge sort for a hub's (a fan-triangulated
      // polygon's vertex may have thousands).
      Half* const first = row.data();
      Half* const last = first + row.size();
      if (row.size() <= 64) {
        for (Half* h = first + 1; h < last; ++h)
          for (Half* g = h; g > first && g[-1].to > g->to; --g) std::swap(g[-1], g[0]);
      } else {
        std::stable_sort(first, last, [](const Half& a, const Half& b) { return a.to < b.to; });
      }
      for (Half* h = first; h != last;) {
        double w = 0.0;
        const Index to = h->to;
        for (; h != last && h->to == to; ++h) w += h->w;
        out.neighbors.push_back(to);
        out.weights.push_back(std::clamp(w, CotangentLaplacian::kMinWeight, CotangentLaplacian::kMaxWeight));
      }
      out.offsets.push_back(static_cast<Index>(out.neighbors.size()));
    }
  };
  CotangentLaplacian L;
  L.offsets.reserve(n + 1);
  L.offsets.push_back(0);
  // Rows are independent: on several threads each builds a range of them,
  // then they are joined in order (the same arrays for any thread count).
  const std::size_t parts = std::clamp<std::size_t>(threads > 0 ? threads : 1, 1, std::max<std::size_t>(n / 8192, 1));
  if (parts == 1) {
    L.neighbors.reserve(first_face[n]);
    L.weights.reserve(first_face[n]);
    build_rows(0, n, L);
    return L;
  }
  std::vector<CotangentLaplacian> ranges(parts);
  parallel_ranges(parts, parts, [&](std::size_t p, std::size_t) { build_rows(n * p / parts, n * (p + 1) / parts, ranges[p]); });
  std::size_t total = 0;
  for (const CotangentLaplacian& r : ranges) total += r.neighbors.size();
  L.neighbors.reserve(total);
  L.weights.reserve(total);
  for (CotangentLaplacian& r : ranges) {
    const Index base = static_cast<Index>(L.neighbors.size());
    for (Index o : r.offsets) L.offsets.push_back(base + o);
    L.neighbors.insert(L.neighbors.end(), r.neighbors.begin(), r.neighbors.end());
    L.weights.insert(L.weights.end(), r.weights.begin(), r.weights.end());
    r = {};
  }
  return L;
}

}  // namespace filigree
