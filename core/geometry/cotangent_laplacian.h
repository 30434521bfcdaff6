#pragma once
// The cotangent Laplacian of a triangle mesh and its differential coordinates
// (thesis eq. 3.3; DESIGN §2.1.5).

#include <span>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// Symmetric edge weights in compressed rows: the neighbours of vertex i are
// neighbors[offsets[i] .. offsets[i+1]), sorted ascending, with weights
// w_ij = (cot α_ij + cot β_ij) / 2 (one cotangent on a boundary edge).
// Robustness: each weight is clamped to [kMinWeight, kMaxWeight], so the
// operator stays a diagonally dominant M-matrix on meshes with obtuse or
// degenerate triangles (a Dirichlet solve with it is always SPD), and no row
// sum is zero.
struct CotangentLaplacian {
  static constexpr double kMinWeight = 1e-4;
  static constexpr double kMaxWeight = 1e4;

  std::vector<Index> offsets;
  std::vector<Index> neighbors;
  std::vector<double> weights;

  std::size_t vertex_count() const { return offsets.empty() ? 0 : offsets.size() - 1; }
  // δ_i = Σ_j w_ij (x_i − x_j), i.e. (L x)_i.
  std::vector<Vec3> apply(std::span<const Vec3> x) const;
};

// Precondition: faces index valid vertices; the mesh may be non-manifold, an
// edge's weight then sums the cotangents of all its faces before clamping.
// Rows are built on up to `threads` threads; the result does not depend on it.
CotangentLaplacian cotangent_laplacian(std::span<const Vec3> positions, std::span<const Triangle> faces, int threads = 1);
inline CotangentLaplacian cotangent_laplacian(const TriMesh& mesh, int threads = 1) {
  return cotangent_laplacian(mesh.positions, mesh.faces, threads);
}

}  // namespace filigree
