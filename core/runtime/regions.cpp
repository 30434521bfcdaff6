#include "runtime/regions.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <exception>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>

#include "geometry/cotangent_laplacian.h"
#include "hierarchy/hierarchy.h"
#include "util/content_hash.h"

namespace filigree {
namespace {

// region_of of a vertex whose region is being searched again.
constexpr Index kPending = kNone - 1;

}  // namespace

double Regions::performance_estimate() const {
  double t = 0.0;
  for (std::size_t r = 0; r < count(); ++r) {
    const double n = static_cast<double>(size(r)), c = static_cast<double>(constraints[r]);
    t += n * n + c * c;
  }
  return t;
}

std::size_t Regions::memory_bytes() const {
  return (offsets.capacity() + vertices.capacity() + constraints.capacity() + region_of.capacity()) * sizeof(Index);
}

Regions find_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut) {
  // From "every vertex in the cut", every free vertex has changed.
  std::vector<Index> free;
  for (Index v = 0; v < laplacian.vertex_count(); ++v)
    if (!in_cut[v]) free.push_back(v);
  Regions out;
  out.region_of.assign(laplacian.vertex_count(), kNone);
  update_regions(laplacian, in_cut, free, out);
  return out;
}

void update_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut,
                    std::span<const Index> changed, Regions& regions) {
  if (changed.empty()) return;
  std::vector<Index>& of = regions.region_of;
  if (of.empty()) of.assign(laplacian.vertex_count(), kNone);
  const Index old_count = static_cast<Index>(regions.count());

  // 1. A region that neither contains nor borders a changed vertex keeps its
  // vertices, its cut neighbours and so its constraints: it is still a
  // component. The others are searched again.
  std::vector<std::uint8_t> dirty(old_count, 0);
  auto mark = [&](Index u) {
    if (of[u] != kNone) dirty[of[u]] = 1;
  };
  for (Index v : changed) {
    mark(v);
    for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) mark(laplacian.neighbors[k]);
  }
  // 2. Pending: the free vertices of those regions and the changed vertices
  // now free. Every free vertex a search can reach is one of them.
  std::vector<Index> seeds;
  auto pend = [&](Index v) {
    if (in_cut[v]) {
      of[v] = kNone;
    } else if (of[v] != kPending) {
      of[v] = kPending;
      seeds.push_back(v);
    }
  };
  for (Index r = 0; r < old_count; ++r)
    if (dirty[r])
      for (Index i = regions.offsets[r]; i < regions.offsets[r + 1]; ++i) pend(regions.vertices[i]);
  for (Index v : changed) pend(v);

  // 3. Search from the pending vertices; new regions get provisional ids
  // after the old ones. Breadth first, with the region's own vertex list as
  // the queue: the rows of the vertices a few places ahead are fetched early,
  // as a search over a large mesh otherwise waits on each row in turn.
  struct Found {
    Index begin, end, constraints;
  };
  std::vector<Found> found;
  std::vector<Index> found_vertices, cut_neighbours;
  for (Index seed : seeds) {
    if (of[seed] != kPending) continue;
    const Index id = old_count + static_cast<Index>(found.size());
    const std::size_t begin = found_vertices.size();
    cut_neighbours.clear();
    found_vertices.push_back(seed);
    of[seed] = id;
    for (std::size_t head = begin; head < found_vertices.size(); ++head) {
      if (head + 4 < found_vertices.size()) {
        const Index ahead = found_vertices[head + 4];
        __builtin_prefetch(&laplacian.neighbors[laplacian.offsets[ahead]]);
      }
      if (head + 2 < found_vertices.size()) {
        const Index ahead = found_vertices[head + 2];
        for (Index k = laplacian.offsets[ahead]; k < laplacian.offsets[ahead + 1]; ++k)
          __builtin_prefetch(&of[laplacian.neighbors[k]]);
      }
      const Index v = found_vertices[head];
      for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) {
        const Index j = laplacian.neighbors[k];
        if (in_cut[j]) {
          cut_neighbours.push_back(j);
        } else if (of[j] == kPending) {
          of[j] = id;
          found_vertices.push_back(j);
          __builtin_prefetch(&laplacian.offsets[j]);
        }
      }
    }
    std::sort(cut_neighbours.begin(), cut_neighbours.end());
    const auto distinct = std::unique(cut_neighbours.begin(), cut_neighbours.end()) - cut_neighbours.begin();
    found.push_back(
        {static_cast<Index>(begin), static_cast<Index>(found_vertices.size()), static_cast<Index>(distinct)});
  }
  // Each found region's vertices in ascending order: sorted one by one, or,
  // when most of the mesh was searched (a cut made from scratch), bucketed by
  // one sweep over the vertices, which is already in order.
  if (found_vertices.size() > of.size() / 8) {
    std::vector<Index> cursor(found.size());
    for (std::size_t i = 0; i < found.size(); ++i) cursor[i] = found[i].begin;
    for (Index v = 0; v < of.size(); ++v)
      if (of[v] != kNone && of[v] >= old_count) found_vertices[cursor[of[v] - old_count]++] = v;
  } else {
    for (const Found& f : found) std::sort(found_vertices.begin() + f.begin, found_vertices.begin() + f.end);
  }

  // 4. Renumber every region by its smallest vertex, as find_regions does:
  // the kept regions are in that order already, so the found ones (sorted)
  // are merged in. Only vertices whose region id changes are rewritten.
  std::vector<Index> found_order(found.size());
  for (Index i = 0; i < found.size(); ++i) found_order[i] = i;
  auto first_found = [&](Index i) { return found_vertices[found[i].begin]; };
  std::sort(found_order.begin(), found_order.end(), [&](Index a, Index b) { return first_found(a) < first_found(b); });
  Regions out;
  std::size_t kept = 0, total = found_vertices.size();
  for (Index r = 0; r < old_count; ++r)
    if (!dirty[r]) ++kept, total += regions.size(r);
  out.offsets.reserve(kept + found.size() + 1);
  out.constraints.reserve(kept + found.size());
  out.vertices.reserve(total);
  auto append = [&](const Index* first, const Index* last, Index constraints, bool rewrite) {
    const Index id = static_cast<Index>(out.count());
    if (rewrite)
      for (const Index* v = first; v != last; ++v) of[*v] = id;
    out.vertices.insert(out.vertices.end(), first, last);
    out.offsets.push_back(static_cast<Index>(out.vertices.size()));
    out.constraints.push_back(constraints);
  };
  std::size_t next_found = 0;
  auto append_found_before = [&](Index limit) {
    for (; next_found < found_order.size() && first_found(found_order[next_found]) < limit; ++next_found) {
      const Found& f = found[found_order[next_found]];
      append(found_vertices.data() + f.begin, found_vertices.data() + f.end, f.constraints, true);
    }
  };
  for (Index r = 0; r < old_count; ++r) {
    if (dirty[r]) continue;
    const Index* first = regions.vertices.data() + regions.offsets[r];
    append_found_before(*first);
    append(first, regions.vertices.data() + regions.offsets[r + 1], regions.constraints[r], out.count() != r);
  }
  append_found_before(kNone);
  out.region_of = std::move(of);
  regions = std::move(out);
}

// ---- RegionSolver

namespace {

// Dense Cholesky, packed by rows: L[i][j] (j ≤ i) at i(i+1)/2 + j, with
// 1/L[i][i] in place of the diagonal so that solves only multiply.
std::size_t packed(std::size_t i, std::size_t j) { return i * (i + 1) / 2 + j; }

// Factorises the packed lower triangle of A in place (Cholesky–Banachiewicz).
bool dense_cholesky(double* l, std::size_t n) {
  for (std::size_t i = 0; i < n; ++i) {
    double* li = l + packed(i, 0);
    for (std::size_t j = 0; j <= i; ++j) {
      const double* lj = l + packed(j, 0);
      double s = li[j];
      for (std::size_t k = 0; k < j; ++k) s -= li[k] * lj[k];
      if (j < i) {
        li[j] = s * lj[j];
      } else {
        if (!(s > 0.0)) return false;
        li[i] = 1.0 / std::sqrt(s);
      }
    }
  }
  return true;
}

// Solves L Lᵀ y = b in place, three columns at once.
void dense_solve(const double* l, std::size_t n, Vec3* y) {
  for (std::size_t i = 0; i < n; ++i) {
    const double* li = l + packed(i, 0);
    Vec3 s = y[i];
    for (std::size_t k = 0; k < i; ++k) s -= li[k] * y[k];
    y[i] = s * li[i];
  }
  for (std::size_t i = n; i-- > 0;) {
    Vec3 s = y[i];
    for (std::size_t k = i + 1; k < n; ++k) s -= l[packed(k, i)] * y[k];
    y[i] = s * l[packed(i, i)];
  }
}

[[noreturn]] void not_factorisable(std::size_t n) {
  throw std::runtime_error("region of " + std::to_string(n) + " vertices could not be factorised");
}

// A thread's own CHOLMOD workspace and settings, for solves.
struct ThreadCholmod {
  cholmod_common common;
  ThreadCholmod() { cholmod_start(&common); }
  ~ThreadCholmod() { cholmod_finish(&common); }
  ThreadCholmod(const ThreadCholmod&) = delete;
  ThreadCholmod& operator=(const ThreadCholmod&) = delete;
};

// CHOLMOD's sparse Cholesky factor, solved with the calling thread's
// workspace: cholmod_solve only reads the factor, so solves with one factor
// may run at once on several threads (Eigen's solve() uses the workspace
// inside the decomposition, which would make them take turns).
class SparseFactor : public Eigen::CholmodDecomposition<Eigen::SparseMatrix<double>, Eigen::Lower> {
 public:
  // Solves for the n × 3 right-hand side b, in place. False if CHOLMOD fails.
  bool solve_in_place(Eigen::MatrixXd& b) const {
    thread_local ThreadCholmod workspace;
    cholmod_dense b_cd = Eigen::viewAsCholmod(b);
    cholmod_dense* x = cholmod_solve(CHOLMOD_A, m_cholmodFactor, &b_cd, &workspace.common);
    if (!x) return false;
    b = Eigen::Map<const Eigen::MatrixXd>(static_cast<const double*>(x->x), b.rows(), b.cols());
    cholmod_free_dense(&x, &workspace.common);
    return true;
  }

  // Heap bytes of CHOLMOD's factor, from its own sizes (supernodal or
  // simplicial): values, their row indices, and the per-column and
  // per-supernode arrays. 0 before factorisation.
  std::size_t factor_bytes() const {
    const cholmod_factor* L = m_cholmodFactor;
    if (!L) return 0;
    const std::size_t index = L->itype == CHOLMOD_LONG ? 8 : 4, value = L->xtype == CHOLMOD_COMPLEX ? 16 : 8;
    std::size_t b = 2 * L->n * index;  // Perm, ColCount
    if (L->is_super) {
      b += L->xsize * value + L->ssize * index + 3 * (L->nsuper + 1) * index;  // x; s; super, pi, px
    } else {
      b += L->nzmax * (value + index) + (4 * L->n + 3) * index;  // x, i; p, nz, next, prev
    }
    return b;
  }
};

}  // namespace

struct RegionSolver::Factor {
  std::vector<Index> vertices;
  std::vector<double> dense;  // n ≤ kDenseMax: the packed dense factor
  std::unique_ptr<SparseFactor> sparse;
  bool made = false;  // factorised (a new factor is factorised by its region's task)
  // A RegionFactors' factor: made once, by whichever solver gets there
  // first (std::call_once), then only read.
  bool shared = false;
  std::once_flag once;

  // Heap bytes: the vertex list, a dense factor, or CHOLMOD's factor as it
  // is (not estimated: the 435k dragon's is ~425 B/vertex, 3× what 16
  // doubles per vertex had said) and the decomposition object.
  std::size_t bytes() const {
    std::size_t b = sizeof(Factor) + 32 + vertices.capacity() * sizeof(Index) + dense.capacity() * sizeof(double);
    if (sparse) b += sizeof(*sparse) + sparse->factor_bytes();
    return b;
  }
};

RegionSolver::RegionSolver(const CotangentLaplacian& laplacian, const std::vector<Vec3>& delta, RegionFactors* shared)
    : laplacian_(laplacian), delta_(delta), shared_(shared) {}

RegionSolver::~RegionSolver() = default;

RegionFactors::RegionFactors() = default;
RegionFactors::~RegionFactors() = default;

std::shared_ptr<RegionSolver::Factor> RegionFactors::find_or_add(std::uint64_t key, const Index* first, std::size_t n) {
  std::lock_guard lock(mutex_);
  const auto [begin, end] = factors_.equal_range(key);
  for (auto it = begin; it != end; ++it)
    if (auto f = it->second.lock(); f && f->vertices.size() == n && std::equal(first, first + n, f->vertices.begin())) return f;
  // Factors no solver holds any more go when a new one comes.
  std::erase_if(factors_, [](const auto& entry) { return entry.second.expired(); });
  auto f = std::make_shared<RegionSolver::Factor>();
  f->vertices.assign(first, first + n);
  f->shared = true;
  factors_.emplace(key, f);
  return f;
}

std::size_t RegionFactors::count() const {
  std::lock_guard lock(mutex_);
  std::size_t alive = 0;
  for (const auto& [key, w] : factors_) alive += !w.expired();
  return alive;
}

std::size_t RegionFactors::memory_bytes() const {
  std::lock_guard lock(mutex_);
  std::size_t bytes = 0;
  for (const auto& [key, w] : factors_)
    if (const auto f = w.lock()) bytes += f->bytes() + 48;
  return bytes;
}

void RegionSolver::factorize(const Regions& regions, std::size_t r, Factor& f) const {
  const Index* first = regions.vertices.data() + regions.offsets[r];
  const std::size_t n = regions.size(r);
  const Index self = static_cast<Index>(r);
  // L_RR: the rows of the region, columns restricted to it; the diagonal keeps
  // every weight, so the constraints make it strictly diagonally dominant (SPD).
  auto local = [&](Index j) { return static_cast<std::size_t>(std::lower_bound(first, first + n, j) - first); };
  // Visits the lower triangle of L_RR (row, column, value), diagonal last per row.
  auto for_each_entry = [&](auto&& put) {
    for (std::size_t i = 0; i < n; ++i) {
      const Index v = first[i];
      double diagonal = 0.0;
      for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
        const Index j = laplacian_.neighbors[k];
        diagonal += laplacian_.weights[k];
        if (j < v && regions.region_of[j] == self) put(i, local(j), -laplacian_.weights[k]);
      }
      put(i, i, diagonal);
    }
  };
  if (n <= kDenseMax) {
    f.dense.assign(n * (n + 1) / 2, 0.0);
    for_each_entry([&](std::size_t i, std::size_t j, double w) { f.dense[packed(i, j)] = w; });
    if (!dense_cholesky(f.dense.data(), n)) not_factorisable(n);
  } else {
    std::vector<Eigen::Triplet<double>> entries;
    for_each_entry([&](std::size_t i, std::size_t j, double w) { entries.emplace_back(static_cast<int>(i), static_cast<int>(j), w); });
    Eigen::SparseMatrix<double> a(static_cast<int>(n), static_cast<int>(n));
    a.setFromTriplets(entries.begin(), entries.end());
    f.sparse = std::make_unique<SparseFactor>();
    f.sparse->compute(a);
    if (f.sparse->info() != Eigen::Success) not_factorisable(n);
  }
  f.made = true;
}

void RegionSolver::solve_region(const Regions& regions, std::size_t r, const Factor* f, std::vector<Vec3>& x,
                                const Calls& calls) const {
  const std::size_t n = regions.size(r);
  const Index* first = regions.vertices.data() + regions.offsets[r];
  const Index self = static_cast<Index>(r);
  if (!f) {
    // A tiny region: its matrix comes from the same rows as its right-hand
    // side, so factorising it here costs less than finding a cached factor.
    // Membership is looked up in its own few vertices, not in region_of.
    double l[kDirectMax * (kDirectMax + 1) / 2];
    std::fill_n(l, n * (n + 1) / 2, 0.0);
    Vec3 y[kDirectMax];
    for (std::size_t i = 0; i < n; ++i) {
      const Index v = first[i];
      Vec3 rhs = calls.term(calls.context, v);
      double diagonal = 0.0;
      for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
        const Index j = laplacian_.neighbors[k];
        const double w = laplacian_.weights[k];
        diagonal += w;
        const std::size_t local = static_cast<std::size_t>(std::find(first, first + n, j) - first);
        if (local == n) {
          rhs += w * x[j];
        } else if (local < i) {
          l[packed(i, local)] = -w;
        }
      }
      l[packed(i, i)] = diagonal;
      y[i] = rhs;
    }
    if (!dense_cholesky(l, n)) not_factorisable(n);
    dense_solve(l, n, y);
    for (std::size_t i = 0; i < n; ++i) x[first[i]] = y[i];
    return;
  }
  auto rhs_of = [&](std::size_t i) {
    const Index v = first[i];
    Vec3 rhs = calls.term(calls.context, v);
    for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
      const Index j = laplacian_.neighbors[k];
      if (regions.region_of[j] != self) rhs += laplacian_.weights[k] * x[j];
    }
    return rhs;
  };
  if (!f->dense.empty()) {
    Vec3 y[kDenseMax];
    for (std::size_t i = 0; i < n; ++i) y[i] = rhs_of(i);
    dense_solve(f->dense.data(), n, y);
    for (std::size_t i = 0; i < n; ++i) x[first[i]] = y[i];
    return;
  }
  Eigen::MatrixXd b(static_cast<Eigen::Index>(n), 3);
  for (std::size_t i = 0; i < n; ++i) b.row(static_cast<Eigen::Index>(i)) = rhs_of(i).transpose();
  if (!f->sparse->solve_in_place(b))
    throw std::runtime_error("CHOLMOD could not solve a region of " + std::to_string(n) + " vertices");
  for (std::size_t i = 0; i < n; ++i) x[first[i]] = b.row(static_cast<Eigen::Index>(i)).transpose();
}

void RegionSolver::prefetch(const Regions& regions, std::size_t r, int step, const std::vector<Vec3>& x,
                            const Calls& calls) const {
  if (regions.size(r) > kDirectMax) return;
  for (Index i = regions.offsets[r]; i < regions.offsets[r + 1]; ++i) {
    const Index v = regions.vertices[i];
    if (step == 0) {
      __builtin_prefetch(&laplacian_.offsets[v]);
      __builtin_prefetch(&delta_[v]);
      if (calls.prefetch) calls.prefetch(calls.context, v);
    } else if (step == 1) {
      __builtin_prefetch(&laplacian_.neighbors[laplacian_.offsets[v]]);
      __builtin_prefetch(&laplacian_.weights[laplacian_.offsets[v]]);
    } else {
      for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k)
        __builtin_prefetch(&x[laplacian_.neighbors[k]]);
    }
  }
}

std::size_t RegionSolver::solve_all(const Regions& regions, std::vector<Vec3>& x, int threads, const Calls& calls) {
  const std::size_t count = regions.count();
  // Find each larger region's factorisation, or make a place for a new one
  // (keyed by a hash of the vertex list; on a collision, probe the next key).
  for (auto& [key, c] : cache_) c.used = false;
  std::vector<Index> large;
  std::vector<Factor*> factors;
  std::vector<std::pair<std::uint64_t, std::shared_ptr<Factor>>> fresh;
  for (std::size_t r = 0; r < count; ++r) {
    const std::size_t n = regions.size(r);
    if (n <= kDirectMax) continue;
    const Index* first = regions.vertices.data() + regions.offsets[r];
    const std::uint64_t hash = hash_bytes(first, n * sizeof(Index));
    Factor* found = nullptr;
    for (std::uint64_t key = hash; !found; ++key) {
      const auto it = cache_.find(key);
      if (it == cache_.end()) break;
      const Factor& f = *it->second.factor;
      if (f.vertices.size() == n && std::equal(first, first + n, f.vertices.begin())) {
        it->second.used = true;
        found = it->second.factor.get();
      }
    }
    if (!found) {
      std::shared_ptr<Factor> f;
      if (shared_ && n >= kSharedMin) {
        f = shared_->find_or_add(hash, first, n);
      } else {
        f = std::make_shared<Factor>();
        f->vertices.assign(first, first + n);
      }
      found = f.get();
      fresh.emplace_back(hash, std::move(f));
    }
    large.push_back(static_cast<Index>(r));
    factors.push_back(found);
  }
  // Factorisations of regions that no longer exist are dropped (a shared one
  // stays while another solver holds it).
  std::erase_if(cache_, [](const auto& entry) { return !entry.second.used; });

  // Tasks, handed out dynamically: the larger regions one by one, largest
  // first, then the tiny ones in blocks. A task makes its region's
  // factorisation if new, then solves, writing only its region's vertices, so
  // the result does not depend on the schedule.
  std::vector<std::size_t> order(large.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return regions.size(large[a]) > regions.size(large[b]); });
  constexpr std::size_t kBlock = 256;
  const std::size_t tasks = order.size() + (count + kBlock - 1) / kBlock;
  std::atomic<std::size_t> next{0}, made{0};
  std::exception_ptr failure;
  std::mutex failure_mutex;
  auto work = [&] {
    try {
      for (std::size_t task = next++; task < tasks; task = next++) {
        if (task < order.size()) {
          const std::size_t i = order[task];
          Factor& f = *factors[i];
          const auto make = [&] {
            factorize(regions, large[i], f);
            ++made;
          };
          if (f.shared) {
            std::call_once(f.once, make);  // another solver may be making it: wait for it
          } else if (!f.made) {
            make();
          }
          solve_region(regions, large[i], &f, x, calls);
          continue;
        }
        // Tiny regions lie scattered over the mesh, so their solves wait on
        // memory: fetch the rows of the regions a few ahead, in the steps
        // the loads depend on each other by, so that the loads overlap.
        const std::size_t begin = (task - order.size()) * kBlock, end = std::min(begin + kBlock, count);
        for (std::size_t r = begin; r < end; ++r) {
          if (r + 12 < end) prefetch(regions, r + 12, 0, x, calls);
          if (r + 6 < end) prefetch(regions, r + 6, 1, x, calls);
          if (r + 3 < end) prefetch(regions, r + 3, 2, x, calls);
          if (regions.size(r) <= kDirectMax) solve_region(regions, r, nullptr, x, calls);
        }
      }
    } catch (...) {
      std::lock_guard lock(failure_mutex);
      if (!failure) failure = std::current_exception();
      next = tasks;
    }
  };
  const int t = std::max(1, std::min<int>(threads, static_cast<int>(tasks)));
  {
    std::vector<std::jthread> pool;
    for (int k = 1; k < t; ++k) pool.emplace_back(work);
    work();
  }
  if (failure) std::rethrow_exception(failure);

  for (auto& [key, f] : fresh) {
    std::uint64_t k = key;
    while (cache_.count(k)) ++k;
    cache_.emplace(k, Cached{std::move(f), true});
  }
  return made;
}

std::size_t RegionSolver::memory_bytes() const {
  std::size_t bytes = 0;
  for (const auto& [key, c] : cache_)
    if (!c.factor->shared) bytes += c.factor->bytes();
  return bytes;
}

}  // namespace filigree
