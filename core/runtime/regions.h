#pragma once
// Regions (DESIGN §2.2.4, thesis §3.5): the connected components, in the
// original mesh's edge graph, of the vertices below the cut. Each is solved as
// a Dirichlet problem L_RR x_R = R·δ_R − L_RB x_B with its neighbouring cut
// vertices fixed (eq. 2.5 with rotated differential coordinates).

#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <type_traits>
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
  // Per vertex: its region, kNone in the cut. May be empty while every
  // vertex is in the cut (a T = 0 cut allocates nothing per vertex).
  std::vector<Index> region_of;

  std::size_t count() const { return offsets.size() - 1; }
  std::size_t size(std::size_t r) const { return offsets[r + 1] - offsets[r]; }
  // The thesis' performance estimate T = Σ (n_i² + c_i²) (eq. 3.12). Exact:
  // the terms are integers, far below 2⁵³.
  double performance_estimate() const;
  std::size_t memory_bytes() const;
};

// `in_cut[v]` marks vertices in the cut mesh. Regions are numbered by their
// smallest vertex, so the result depends only on the cut.
Regions find_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut);

// Brings `regions` — find_regions' result for an earlier `in_cut`, or an
// empty Regions if every vertex was in the cut — up to date after the
// vertices `changed` entered or left the cut (repeats, and vertices that
// changed back, are fine). Only the regions that contain or border a changed
// vertex are searched again; the rest are renumbered, O(their vertices). The
// result equals find_regions(laplacian, in_cut).
void update_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut,
                    std::span<const Index> changed, Regions& regions);

class RegionFactors;

// Solves regions, keeping each region's Cholesky factorisation for as long as
// a region with exactly the same vertices exists: dense for small regions (a
// sparse solver's fixed cost per call would dominate), CHOLMOD's sparse one
// above. Most regions of a finite T hold a vertex or two (percolation, DESIGN
// §2.2.4); those are factorised afresh every solve, from the rows their
// right-hand side reads anyway, which costs less than finding a cached factor.
// Regions of kSharedMin vertices or more (T = ∞'s whole mesh, large regions
// of a finite T) take their factorisation from `shared`, if given.
class RegionSolver {
 public:
  // `shared` (may be null) must outlive the solver; it is the mesh's, shared
  // by the solvers of every session of it (DeformerModel::region_factors).
  RegionSolver(const CotangentLaplacian& laplacian, const std::vector<Vec3>& delta, RegionFactors* shared = nullptr);
  ~RegionSolver();

  // Writes the solution of every region into `x` (cut vertices of `x` are the
  // fixed values). `rotation(v)` gives the rotation applied to δ_v; it is
  // called once per region vertex just before that vertex's region is solved,
  // from up to `threads` threads at once, and may read x at v and at v's mesh
  // neighbours (those still hold this call's input: a region's neighbours are
  // its own vertices or cut vertices). Regions are factorised and solved on
  // `threads` threads; results do not depend on it.
  // Returns the number of factorisations this call made for its cache
  // (regions of more than kDirectMax vertices that are new).
  // If `rotation` also has a `prefetch(Index v)` member, it is called a few
  // regions ahead of rotation(v), so that what rotation(v) reads arrives in
  // time (tiny regions lie scattered, and their solves wait on memory).
  template <class RotationOf>
  std::size_t solve(const Regions& regions, std::vector<Vec3>& x, int threads, RotationOf&& rotation) {
    using F = std::remove_reference_t<RotationOf>;
    struct Context {
      const F* rotation;
      const std::vector<Vec3>* delta;
    } context{&rotation, &delta_};
    Calls calls{[](const void* c, Index v) -> Vec3 {
                  const auto* k = static_cast<const Context*>(c);
                  return (*k->rotation)(v) * (*k->delta)[v];
                },
                nullptr, &context};
    if constexpr (requires(const F& f, Index v) { f.prefetch(v); })
      calls.prefetch = [](const void* c, Index v) { static_cast<const Context*>(c)->rotation->prefetch(v); };
    return solve_all(regions, x, threads, calls);
  }

  // As solve(), with the whole term of each region vertex's row given:
  // `term(v)` replaces R_v·δ_v (local–global steps give Σ_j w_vj·½(R_v + R_j)
  // (p_v − p_j)). Same threads and reads as solve()'s rotation.
  template <class TermOf>
  std::size_t solve_terms(const Regions& regions, std::vector<Vec3>& x, int threads, TermOf&& term) {
    using F = std::remove_reference_t<TermOf>;
    Calls calls{[](const void* f, Index v) -> Vec3 { return (*static_cast<const F*>(f))(v); }, nullptr, &term};
    return solve_all(regions, x, threads, calls);
  }

  // Factorisations this solver holds, shared ones included.
  std::size_t cached_factorizations() const { return cache_.size(); }
  // Heap bytes of the factorisations only this solver holds (estimated for
  // CHOLMOD's); shared ones are counted by their RegionFactors.
  std::size_t memory_bytes() const;

  // Regions of at most this many vertices are solved without the cache.
  static constexpr std::size_t kDirectMax = 8;
  // Regions of at most this many vertices get a dense factorisation.
  static constexpr std::size_t kDenseMax = 32;
  // Regions of at least this many vertices share their factorisation.
  static constexpr std::size_t kSharedMin = 1024;

 private:
  friend class RegionFactors;
  struct Factor;
  // The caller's term of each row (R_v·δ_v, or given), type-erased.
  struct Calls {
    Vec3 (*term)(const void*, Index);
    void (*prefetch)(const void*, Index);  // may be null
    const void* context;
  };
  std::size_t solve_all(const Regions& regions, std::vector<Vec3>& x, int threads, const Calls& calls);
  void factorize(const Regions& regions, std::size_t r, Factor& f) const;
  // Step 0, 1, 2 of fetching the rows a tiny region r's solve reads.
  void prefetch(const Regions& regions, std::size_t r, int step, const std::vector<Vec3>& x, const Calls& calls) const;
  // `f` is null for a region of at most kDirectMax vertices.
  void solve_region(const Regions& regions, std::size_t r, const Factor* f, std::vector<Vec3>& x,
                    const Calls& calls) const;

  const CotangentLaplacian& laplacian_;
  const std::vector<Vec3>& delta_;
  RegionFactors* shared_;
  struct Cached {
    std::shared_ptr<Factor> factor;
    bool used = false;  // by this solve's regions (this solver's own mark: a shared factor has several)
  };
  std::unordered_map<std::uint64_t, Cached> cache_;
};

// The factorisations of large regions shared by every RegionSolver of one
// mesh: a region's matrix depends on its vertices alone, so the first solver
// whose regions include it factorises it, and the others use that factor
// (T = ∞: one whole-mesh factorisation, 2 s and ~200 MB at 435k vertices,
// for all sessions instead of each). A factor lives while some solver holds
// its region; once made it is only read, and solves with it run at once,
// each with its thread's CHOLMOD workspace. Thread-safe.
class RegionFactors {
 public:
  RegionFactors();
  ~RegionFactors();
  RegionFactors(const RegionFactors&) = delete;
  RegionFactors& operator=(const RegionFactors&) = delete;

  // Factorisations some solver holds now.
  std::size_t count() const;
  // Their heap bytes (estimated for CHOLMOD's).
  std::size_t memory_bytes() const;

 private:
  friend class RegionSolver;
  // The factor of the region with vertices [first, first + n) (ascending),
  // made empty if no solver holds one; `key` is their hash.
  std::shared_ptr<RegionSolver::Factor> find_or_add(std::uint64_t key, const Index* first, std::size_t n);

  mutable std::mutex mutex_;
  std::unordered_multimap<std::uint64_t, std::weak_ptr<RegionSolver::Factor>> factors_;
};

}  // namespace filigree
