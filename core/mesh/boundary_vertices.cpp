#include "mesh/boundary_vertices.h"

#include <algorithm>

#include "util/parallel_for.h"

namespace filigree {

std::vector<std::uint8_t> boundary_vertices(const TriMesh& mesh, int threads) {
  const std::size_t n = mesh.positions.size();
  // Faces by vertex (counting sort).
  std::vector<std::size_t> offsets(n + 1, 0);
  for (const Triangle& f : mesh.faces)
    for (Index v : f) ++offsets[v + 1];
  for (std::size_t v = 0; v < n; ++v) offsets[v + 1] += offsets[v];
  std::vector<Index> faces(offsets[n]);
  {
    std::vector<std::size_t> at(offsets.begin(), offsets.end() - 1);
    for (Index f = 0; f < mesh.faces.size(); ++f)
      for (Index v : mesh.faces[f]) faces[at[v]++] = f;
  }
  std::vector<std::uint8_t> boundary(n, 0);
  parallel_ranges(n, static_cast<std::size_t>(std::clamp(threads, 1, 64)), [&](std::size_t begin, std::size_t end) {
    std::vector<Index> next, previous;
    for (std::size_t v = begin; v < end; ++v) {
      next.clear();
      previous.clear();
      for (std::size_t i = offsets[v]; i < offsets[v + 1]; ++i) {
        const Triangle& t = mesh.faces[faces[i]];
        const int c = t[0] == v ? 0 : t[1] == v ? 1 : 2;
        next.push_back(t[(c + 1) % 3]);
        previous.push_back(t[(c + 2) % 3]);
      }
      std::sort(next.begin(), next.end());
      std::sort(previous.begin(), previous.end());
      boundary[v] = next != previous;
    }
  });
  return boundary;
}

}  // namespace filigree
