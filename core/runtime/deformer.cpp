#include "runtime/deformer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>

#include "geometry/best_fit_rotation.h"
#include "geometry/cotangent_laplacian.h"
#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"
#include "runtime/deformer_model.h"
#include "runtime/direct_recovery.h"
#include "runtime/regions.h"
#include "runtime/rotation_interpolation.h"
#include "util/buffer_pool.h"
#include "util/parallel_for.h"

namespace filigree {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

void check_threshold(double threshold) {
  if (std::isnan(threshold) || threshold < 0.0) throw std::invalid_argument("threshold must be ≥ 0 (or ∞)");
}

}  // namespace

// Region optimisation's per-session state, made when T first leaves 0 and
// dropped when it returns there: a T = 0 session holds only its recovery
// scratch.
struct Deformer::Optimised {
  BaseRotations rotations;
  AdaptiveCut cut;
  RegionSolver solver;
  std::vector<Vec3> positions;  // the last frame's result (rest before the first): the cut scores it
  std::vector<Eigen::Quaterniond> base_q;
  // Edge terms: the vertices whose rotations they read (the region vertices
  // and their cut neighbours), each one's slot in `fit` (kNone for the
  // others), and those rotations: 4 bytes a vertex, and 72 a fitted one (a
  // small finite T's regions are a few thousand).
  std::vector<Index> fitted;
  std::vector<Index> slot;
  std::vector<Eigen::Matrix3d> fit;
  const Eigen::Matrix3d& rotation_of(Index v) const { return fit[slot[v]]; }

  Optimised(const DeformerModel& m, const DeformerOptions& o)
      : rotations(m.hierarchy().base_mesh(), o.rotation), cut(m.node_graph(), m.laplacian(), o.threshold),
        solver(m.laplacian(), m.differential_coordinates(), &m.region_factors()), positions(m.hierarchy().rest_positions.to_vector()) {
    cut.reset(o.threshold);
  }
};

struct Deformer::State {
  RecoveryWorkspace workspace;
  std::unique_ptr<Optimised> optimised;
  std::unique_ptr<CutState> full_cut;  // cut_state() at T = 0, made when asked
  // A restored cut is the one its frame was computed with: the next deform()
  // must not update it again.
  bool cut_restored = false;
};

Deformer::Deformer(std::shared_ptr<const DeformerModel> model, const DeformerOptions& options)
    : model_(std::move(model)), options_(options), s_(std::make_unique<State>()) {
  if (!model_) throw std::invalid_argument("a deformer needs a model");
  check_threshold(options.threshold);
  if (options.threads < 1) throw std::invalid_argument("threads must be ≥ 1");
  if (options.local_global_iterations < 0) throw std::invalid_argument("local-global iterations must be ≥ 0");
  if (!(options.regions_budget_ms >= 0.0) || std::isinf(options.regions_budget_ms))
    throw std::invalid_argument("the regions' time budget must be a finite number of ms ≥ 0");
  if (options.regions_budget_ms > 0.0) {
    if (std::isinf(options.threshold)) throw std::invalid_argument("T = ∞ has no time budget: it optimises the whole mesh");
    if (options_.threshold <= 0.0) options_.threshold = DeformerOptions::kBudgetStartT;
  }
  if (options_.threshold > 0.0) optimised();
}

Deformer::Deformer(const Hierarchy& h, const DeformerOptions& options)
    : Deformer(DeformerModel::create(std::shared_ptr<const Hierarchy>(&h, [](const Hierarchy*) {})), options) {}

Deformer::~Deformer() = default;

std::size_t Deformer::base_vertex_count() const { return model_->hierarchy().base_vertices.size(); }

std::size_t Deformer::vertex_count() const { return model_->hierarchy().vertex_count(); }

Deformer::Optimised& Deformer::optimised() {
  if (!s_->optimised) {
    model_->derive_for_cuts();
    s_->optimised = std::make_unique<Optimised>(*model_, options_);
  }
  return *s_->optimised;
}

const std::vector<Index>& Deformer::region_of_vertex() const {
  static const std::vector<Index> none;
  return s_->optimised ? s_->optimised->cut.regions().region_of : none;
}

const CutState& Deformer::cut_state() const {
  if (s_->optimised) return s_->optimised->cut.state();
  if (!s_->full_cut) {
    s_->full_cut = std::make_unique<CutState>(CutState::full(model_->hierarchy()));
  }
  return *s_->full_cut;
}

void Deformer::set_threads(int threads) {
  if (threads < 1) throw std::invalid_argument("threads must be ≥ 1");
  options_.threads = threads;
}

void Deformer::set_threshold(double threshold) {
  check_threshold(threshold);
  options_.threshold = threshold;
  if (threshold <= 0.0) {
    s_->optimised.reset();  // direct recovery only: free the cut and the factorisations
    s_->cut_restored = false;
  } else if (s_->optimised) {
    s_->optimised->cut.set_threshold(threshold);
  }
}

CutSnapshot Deformer::cut_snapshot() const {
  return s_->optimised ? s_->optimised->cut.snapshot() : CutSnapshot{};
}

void Deformer::restore_cut(const CutSnapshot& snapshot) {
  if (!s_->optimised || snapshot.empty()) return;
  s_->optimised->cut.restore(snapshot);
  s_->cut_restored = true;
}

std::size_t Deformer::memory_bytes() const {
  std::size_t bytes = s_->workspace.xyzw.capacity() * sizeof(float);
  if (const Optimised* o = s_->optimised.get())
    bytes += o->positions.capacity() * sizeof(Vec3) + o->cut.memory_bytes() + o->solver.memory_bytes() +
             (o->fitted.capacity() + o->slot.capacity()) * sizeof(Index) + o->fit.capacity() * sizeof(Eigen::Matrix3d);
  return bytes;
}

DeformResult Deformer::deform(const Pose& pose) {
  DeformResult r;
  r.positions.resize(vertex_count());
  r.stats = deform(pose, r.positions);
  return r;
}

namespace {

// Direct recovery's scratch, borrowed from the model for one frame and given
// back however the frame ends.
class LentScratch {
 public:
  LentScratch(const DeformerModel& model, RecoveryWorkspace& ws) : pool_(model.recovery_scratch()), ws_(ws) {
    if (ws_.xyzw.capacity() == 0) ws_.xyzw = pool_.take(model.recovery().scratch_floats());
  }
  ~LentScratch() { pool_.give(std::exchange(ws_.xyzw, {})); }
  LentScratch(const LentScratch&) = delete;
  LentScratch& operator=(const LentScratch&) = delete;

 private:
  BufferPool<float>& pool_;
  RecoveryWorkspace& ws_;
};

}  // namespace

FrameStats Deformer::deform(const Pose& pose, std::span<Vec3> out) {
  const Hierarchy& h = model_->hierarchy();
  validate_pose(pose, h.base_vertices.size());
  if (out.size() != h.vertex_count())
    throw std::invalid_argument("output has room for " + std::to_string(out.size()) + " vertices, the mesh has " +
                                std::to_string(h.vertex_count()));
  const auto start = Clock::now();
  const DirectRecovery& recovery = model_->recovery();
  const LentScratch scratch(*model_, s_->workspace);
  FrameStats stats;
  stats.threshold = options_.threshold;

  if (options_.threshold <= 0.0) {
    // T = 0: every node recovered, straight into the caller's buffer.
    const auto t = Clock::now();
    recovery.recover(pose.positions, s_->workspace, out, options_.threads);
    stats.recover_ms = ms_since(t);
    stats.cut_nodes = h.node_count();
    stats.cut_vertices = h.vertex_count();
    stats.total_ms = ms_since(start);
    return stats;
  }

  Optimised& s = optimised();
  // 1. Move the cut where the last frame deformed acutely (thesis §3.3).
  auto t = Clock::now();
  if (options_.update_cut && !std::exchange(s_->cut_restored, false)) {
    const std::size_t nodes = h.node_count();
    const std::size_t eval = options_.cut_eval_budget ? options_.cut_eval_budget : std::max<std::size_t>(2048, nodes / 32);
    const std::size_t moves = options_.cut_move_budget ? options_.cut_move_budget : std::max<std::size_t>(128, nodes / 256);
    stats.cut_moves = s.cut.update(s.positions, eval, moves, options_.threads);
  }
  stats.cut_converged = !options_.update_cut || s.cut.converged();  // a pinned cut never moves
  stats.cut_update_ms = ms_since(t);

  // 2. Direct recovery of the cut, parents first (thesis eq. 3.10).
  t = Clock::now();
  std::vector<Vec3>& x = s.positions;
  const CutState& cut = s.cut.state();
  if (cut.recovered_count() > 0) {
    // Writes every vertex; the regions below overwrite theirs.
    recovery.recover(pose.positions, s_->workspace, x, options_.threads);
  } else {
    for (Index i = 0; i < h.base_vertices.size(); ++i) x[h.base_vertices[i]] = pose.positions[i];
  }
  stats.recover_ms = ms_since(t);

  // 3. Rotations of the base vertices; only regions use them, direct
  // recovery carries its own frames.
  const Regions& regions = s.cut.regions();
  t = Clock::now();
  if (regions.count() > 0) s.rotations.compute(pose.positions, s.base_q, options_.threads);
  stats.rotations_ms = ms_since(t);

  // 4. Regions: Dirichlet solves with rotated differential coordinates.
  t = Clock::now();
  const auto& corners = model_->maps_corners();
  auto interpolated = [&](Index v) {
    const auto& c = corners[v];
    return interpolate_rotation({s.base_q[c[0]], s.base_q[c[1]], s.base_q[c[2]]}, h.maps_barycentric(v)).toRotationMatrix();
  };
  if (regions.count() > 0 && options_.region_terms == RegionTerms::kEdgeRotations) {
    collect_fitted(s);
    parallel_for(s.fitted.size(), options_.threads, [&](std::size_t i) { s.fit[i] = interpolated(s.fitted[i]); });
    stats.factorizations = solve_edge_terms(s, x);
  } else {
    stats.factorizations = s.solver.solve(regions, x, options_.threads, interpolated);
  }
  if (options_.local_global_iterations > 0) {
    if (options_.region_terms != RegionTerms::kEdgeRotations) collect_fitted(s);
    local_global(s, x);
  }
  stats.regions_ms = ms_since(t);
  if (options_.regions_budget_ms > 0.0 && !std::isinf(options_.threshold)) {
    // The next frame's T, toward the budget: T bounds Σ(n_i² + c_i²), and
    // the regions' time grows with it. Within 25% of the budget T stays, so
    // that the cut can settle.
    const double scale = std::clamp(options_.regions_budget_ms / std::max(stats.regions_ms, 1e-3), 0.5, 2.0);
    const double next = std::clamp(options_.threshold * scale, DeformerOptions::kMinBudgetT, DeformerOptions::kMaxBudgetT);
    if ((scale < 0.8 || scale > 1.25) && next != options_.threshold) {
      options_.threshold = next;
      s.cut.set_threshold(next);
    }
  }
  std::copy(x.begin(), x.end(), out.begin());

  stats.cut_nodes = cut.recovered_count();
  stats.cut_vertices = h.base_vertices.size() + stats.cut_nodes;
  stats.regions = regions.count();
  for (std::size_t r = 0; r < regions.count(); ++r) stats.region_sizes.push_back(regions.size(r));
  std::sort(stats.region_sizes.rbegin(), stats.region_sizes.rend());
  stats.region_vertices = regions.vertices.size();
  stats.performance_estimate = regions.performance_estimate();
  stats.total_ms = ms_since(start);
  return stats;
}

void Deformer::collect_fitted(Optimised& s) const {
  const CotangentLaplacian& laplacian = model_->laplacian();
  const std::size_t n = model_->hierarchy().vertex_count();
  if (s.slot.size() != n) s.slot.assign(n, kNone);
  for (const Index v : s.fitted) s.slot[v] = kNone;  // the last frame's
  s.fitted.clear();
  const auto take = [&](Index v) {
    if (s.slot[v] != kNone) return;
    s.slot[v] = static_cast<Index>(s.fitted.size());
    s.fitted.push_back(v);
  };
  for (const Index v : s.cut.regions().vertices) {
    take(v);
    for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) take(laplacian.neighbors[k]);
  }
  s.fit.resize(s.fitted.size());
}

std::size_t Deformer::solve_edge_terms(Optimised& s, std::vector<Vec3>& x) const {
  const Hierarchy& h = model_->hierarchy();
  const CotangentLaplacian& laplacian = model_->laplacian();
  return s.solver.solve_terms(s.cut.regions(), x, options_.threads, [&](Index v) {
    // ½ R_v Σ_j w_vj (p_v − p_j) + ½ Σ_j w_vj R_j (p_v − p_j)
    Vec3 own = Vec3::Zero(), others = Vec3::Zero();
    for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) {
      const Index j = laplacian.neighbors[k];
      const Vec3 e = laplacian.weights[k] * (h.rest_positions[v] - h.rest_positions[j]);
      own += e;
      others += s.rotation_of(j) * e;
    }
    return Vec3(0.5 * (s.rotation_of(v) * own + others));
  });
}

// Local–global iterations (as-rigid-as-possible, Sorkine & Alexa 2007) on
// the regions, from the solve above: the local step fits each rotation to
// its ring on the current result; the global step solves with edge terms,
// the exact minimiser, for those rotations, of the ARAP energy
// Σ w_vj ‖(x_v − x_j) − R_v (p_v − p_j)‖² over the edges at the regions.
// Both steps only lower that energy, so an iteration never raises it (with
// the thesis' R_v·δ_v terms there was no such energy: on needle triangles
// iterating diverged).
void Deformer::local_global(Optimised& s, std::vector<Vec3>& x) const {
  const Hierarchy& h = model_->hierarchy();
  const CotangentLaplacian& laplacian = model_->laplacian();
  for (int it = 0; it < options_.local_global_iterations; ++it) {
    parallel_for(s.fitted.size(), options_.threads, [&](std::size_t i) {
      const Index v = s.fitted[i];
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) {
        const Index j = laplacian.neighbors[k];
        cov += laplacian.weights[k] * (h.rest_positions[j] - h.rest_positions[v]) * (x[j] - x[v]).transpose();
      }
      s.fit[i] = best_fit_rotation(cov);
    });
    solve_edge_terms(s, x);
  }
}

}  // namespace filigree
