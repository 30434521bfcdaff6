#include "mesh/vertex_order.h"

#include <algorithm>
#include <cstdint>

namespace filigree {
namespace {

// Spreads the low 21 bits of x so that two zero bits follow each.
std::uint64_t spread(std::uint64_t x) {
  x &= 0x1fffff;
  x = (x | x << 32) & 0x1f00000000ffffULL;
  x = (x | x << 16) & 0x1f0000ff0000ffULL;
  x = (x | x << 8) & 0x100f00f00f00f00fULL;
  x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
  x = (x | x << 2) & 0x1249249249249249ULL;
  return x;
}

}  // namespace

std::vector<Index> locality_order(std::span<const Vec3> positions) {
  std::vector<Index> order(positions.size());
  if (positions.empty()) return order;
  Vec3 lo = positions[0], hi = lo;
  for (const Vec3& p : positions) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const double extent = std::max((hi - lo).maxCoeff(), 1e-300);
  std::vector<std::pair<std::uint64_t, Index>> keyed(positions.size());
  for (Index i = 0; i < positions.size(); ++i) {
    std::uint64_t code = 0;
    for (int axis = 0; axis < 3; ++axis) {
      const double t = std::clamp((positions[i][axis] - lo[axis]) / extent, 0.0, 1.0);
      code |= spread(static_cast<std::uint64_t>(t * 2097151.0)) << axis;
    }
    keyed[i] = {code, i};
  }
  std::sort(keyed.begin(), keyed.end());
  for (std::size_t i = 0; i < keyed.size(); ++i) order[i] = keyed[i].second;
  return order;
}

TriMesh permute_vertices(const TriMesh& mesh, const std::vector<Index>& new_to_old) {
  std::vector<Index> old_to_new(mesh.positions.size());
  TriMesh out;
  out.positions.resize(mesh.positions.size());
  for (Index i = 0; i < new_to_old.size(); ++i) {
    out.positions[i] = mesh.positions[new_to_old[i]];
    old_to_new[new_to_old[i]] = i;
  }
  out.faces.reserve(mesh.faces.size());
  for (const Triangle& f : mesh.faces) out.faces.push_back({old_to_new[f[0]], old_to_new[f[1]], old_to_new[f[2]]});
  return out;
}

}  // namespace filigree
