#include "runtime/regions.h"

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <thread>

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>

#include "geometry/cotangent_laplacian.h"
#include "hierarchy/hierarchy.h"
#include "util/content_hash.h"

namespace filigree {

double Regions::performance_estimate() const {
  double t = 0.0;
  for (std::size_t r = 0; r < count(); ++r) {
    const double n = static_cast<double>(size(r)), c = static_cast<double>(constraints[r]);
    t += n * n + c * c;
  }
  return t;
}

Regions find_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut) {
  const std::size_t n = laplacian.vertex_count();
  Regions out;
  out.region_of.assign(n, kNone);
  out.local_index.assign(n, kNone);
  std::vector<Index> stack, touched_cut;
  std::vector<Index> seen_cut(n, kNone);  // region that last counted this cut vertex
  for (Index seed = 0; seed < n; ++seed) {
    if (in_cut[seed] || out.region_of[seed] != kNone) continue;
    const Index r = static_cast<Index>(out.count());
    const std::size_t begin = out.vertices.size();
    Index constraints = 0;
    stack.assign(1, seed);
    out.region_of[seed] = r;
    while (!stack.empty()) {
      const Index v = stack.back();
      stack.pop_back();
      out.vertices.push_back(v);
      for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) {
        const Index j = laplacian.neighbors[k];
        if (in_cut[j]) {
          if (seen_cut[j] != r) seen_cut[j] = r, ++constraints;
        } else if (out.region_of[j] == kNone) {
          out.region_of[j] = r;
          stack.push_back(j);
        }
      }
    }
    std::sort(out.vertices.begin() + static_cast<std::ptrdiff_t>(begin), out.vertices.end());
    for (std::size_t i = begin; i < out.vertices.size(); ++i) out.local_index[out.vertices[i]] = static_cast<Index>(i - begin);
    out.offsets.push_back(static_cast<Index>(out.vertices.size()));
    out.constraints.push_back(constraints);
  }
  return out;
}

struct RegionSolver::Factor {
  std::vector<Index> vertices;
  Eigen::CholmodDecomposition<Eigen::SparseMatrix<double>, Eigen::Lower> cholesky;
  bool used = false;
};

RegionSolver::RegionSolver(const CotangentLaplacian& laplacian, const std::vector<Vec3>& delta)
    : laplacian_(laplacian), delta_(delta) {}

RegionSolver::~RegionSolver() = default;

RegionSolver::Factor& RegionSolver::factor_for(const Regions& regions, std::size_t r, std::size_t& made) {
  const Index* first = regions.vertices.data() + regions.offsets[r];
  const std::size_t n = regions.size(r);
  // Keyed by a hash of the vertex list; on a collision, probe the next key.
  std::uint64_t key = hash_bytes(first, n * sizeof(Index));
  for (auto it = cache_.find(key); it != cache_.end(); it = cache_.find(++key)) {
    if (it->second->vertices.size() == n && std::equal(first, first + n, it->second->vertices.begin())) {
      it->second->used = true;
      return *it->second;
    }
  }
  // L_RR: the rows of the region, columns restricted to it; the diagonal keeps
  // every weight, so the constraints make it strictly diagonally dominant (SPD).
  std::vector<Eigen::Triplet<double>> entries;
  for (std::size_t i = 0; i < n; ++i) {
    const Index v = first[i];
    double diagonal = 0.0;
    for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
      const Index j = laplacian_.neighbors[k];
      diagonal += laplacian_.weights[k];
      if (regions.region_of[j] == r && regions.local_index[j] < i)
        entries.emplace_back(static_cast<int>(i), static_cast<int>(regions.local_index[j]), -laplacian_.weights[k]);
    }
    entries.emplace_back(static_cast<int>(i), static_cast<int>(i), diagonal);
  }
  Eigen::SparseMatrix<double> a(static_cast<int>(n), static_cast<int>(n));
  a.setFromTriplets(entries.begin(), entries.end());
  auto f = std::make_unique<Factor>();
  f->vertices.assign(first, first + n);
  f->cholesky.compute(a);
  if (f->cholesky.info() != Eigen::Success)
    throw std::runtime_error("region of " + std::to_string(n) + " vertices could not be factorised");
  f->used = true;
  ++made;
  Factor& ref = *f;
  cache_[key] = std::move(f);
  return ref;
}

void RegionSolver::solve_region(const Regions& regions, std::size_t r, Factor& f, std::vector<Vec3>& x,
                                const std::vector<Eigen::Matrix3d>& rotations) const {
  const std::size_t n = regions.size(r);
  Eigen::MatrixX3d b(static_cast<Eigen::Index>(n), 3);
  for (std::size_t i = 0; i < n; ++i) {
    const Index v = f.vertices[i];
    Vec3 rhs = rotations[v] * delta_[v];
    for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
      const Index j = laplacian_.neighbors[k];
      if (regions.region_of[j] != r) rhs += laplacian_.weights[k] * x[j];
    }
    b.row(static_cast<Eigen::Index>(i)) = rhs.transpose();
  }
  const Eigen::MatrixX3d sol = f.cholesky.solve(b);
  for (std::size_t i = 0; i < n; ++i) x[f.vertices[i]] = sol.row(static_cast<Eigen::Index>(i)).transpose();
}

void RegionSolver::solve_all(const Regions& regions, std::vector<Vec3>& x, int threads,
                             const std::vector<Eigen::Matrix3d>& rotations, std::size_t& made) {
  for (auto& [key, f] : cache_) f->used = false;
  std::vector<Factor*> factors(regions.count());
  for (std::size_t r = 0; r < regions.count(); ++r) factors[r] = &factor_for(regions, r, made);
  // Factorisations of regions that no longer exist are dropped.
  std::erase_if(cache_, [](const auto& entry) { return !entry.second->used; });

  // Largest regions first, handed out dynamically; each region writes only its
  // own vertices, so the result does not depend on the schedule.
  std::vector<std::size_t> order(regions.count());
  for (std::size_t r = 0; r < order.size(); ++r) order[r] = r;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return regions.size(a) > regions.size(b); });
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t i = next++; i < order.size(); i = next++) solve_region(regions, order[i], *factors[order[i]], x, rotations);
  };
  const int t = std::max(1, std::min<int>(threads, static_cast<int>(order.size())));
  std::vector<std::jthread> pool;
  for (int k = 1; k < t; ++k) pool.emplace_back(work);
  work();
}

}  // namespace filigree
