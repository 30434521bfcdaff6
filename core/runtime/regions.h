#pragma once
// Regions (DESIGN §2.2.4, thesis §3.5): the connected components, in the
// original mesh's edge graph, of the vertices below the cut. Each is solved as
// a Dirichlet problem L_RR x_R = R·δ_R − L_RB x_B with its neighbouring cut
// vertices fixed (eq. 2.5 with rotated differential coordinates).

#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>

#include "mesh/tri_mesh.h"

namespace filigree {

struct CotangentLaplacian;

struct Regions {
  std::vector<Index> offsets{0};       // region r is vertices[offsets[r] .. offsets[r+1])
  std::vector<Index> vertices;         // ascending within a region
  std::vector<Index> constraints;      // per region: cut vertices adjacent to it (c_i)
  std::vector<Index> region_of;        // per vertex: its region, kNone in the cut
  std::vector<Index> local_index;      // per region vertex: its position in its region

  std::size_t count() const { return offsets.size() - 1; }
  std::size_t size(std::size_t r) const { return offsets[r + 1] - offsets[r]; }
  // The thesis' performance estimate T = Σ (n_i² + c_i²) (eq. 3.12).
  double performance_estimate() const;
};

// `in_cut[v]` marks vertices in the cut mesh. Regions are numbered by their
// smallest vertex, so the result depends only on the cut.
Regions find_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut);

// Solves regions, keeping each region's sparse Cholesky factorisation
// (CHOLMOD) for as long as a region with exactly the same vertices exists.
class RegionSolver {
 public:
  RegionSolver(const CotangentLaplacian& laplacian, const std::vector<Vec3>& delta);
  ~RegionSolver();

  // Writes the solution of every region into `x` (cut vertices of `x` are the
  // fixed values). `rotation(v)` gives the rotation applied to δ_v.
  // Regions are solved on `threads` threads; results do not depend on it.
  // Returns the number of factorisations this call performed.
  template <class RotationOf>
  std::size_t solve(const Regions& regions, std::vector<Vec3>& x, int threads, RotationOf&& rotation);

  std::size_t cached_factorizations() const { return cache_.size(); }

 private:
  struct Factor;
  // Factorises (or finds) region r; not thread-safe, called before the solves.
  Factor& factor_for(const Regions& regions, std::size_t r, std::size_t& new_factorizations);
  void solve_region(const Regions& regions, std::size_t r, Factor& f, std::vector<Vec3>& x,
                    const std::vector<Eigen::Matrix3d>& rotations) const;
  void solve_all(const Regions& regions, std::vector<Vec3>& x, int threads, const std::vector<Eigen::Matrix3d>& rotations,
                 std::size_t& new_factorizations);

  const CotangentLaplacian& laplacian_;
  const std::vector<Vec3>& delta_;
  std::unordered_map<std::uint64_t, std::unique_ptr<Factor>> cache_;
  std::vector<Eigen::Matrix3d> rotations_;  // per vertex scratch, filled for region vertices
};

template <class RotationOf>
std::size_t RegionSolver::solve(const Regions& regions, std::vector<Vec3>& x, int threads, RotationOf&& rotation) {
  rotations_.resize(x.size());
  for (Index v : regions.vertices) rotations_[v] = rotation(v);
  std::size_t made = 0;
  solve_all(regions, x, threads, rotations_, made);
  return made;
}

}  // namespace filigree
