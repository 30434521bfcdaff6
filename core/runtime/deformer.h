#pragma once
// The runtime (DESIGN §2.2): given positions for the base vertices, the
// full-resolution detail-preserving deformation, with the cut threshold T as
// the quality/speed knob. Built once from a Hierarchy, then deform() per pose.

#include <limits>
#include <memory>
#include <span>
#include <vector>

#include "runtime/base_rotations.h"
#include "runtime/cut_snapshot.h"
#include "runtime/pose.h"

namespace filigree {

struct Hierarchy;
class CutState;
class DeformerModel;

// How region optimisation rotates the rest mesh's geometry into a frame's
// right-hand side.
enum class RegionTerms {
  // Each edge by the mean of its ends' rotations, Σ_j w_vj·½(R_v + R_j)(p_v − p_j):
  // the as-rigid-as-possible global step. The default: measured against the
  // analytic truth (bench/runtime_bench, Armadillo, T = ∞) 12–26% lower RMS
  // than the thesis' form on bend, twist, bump and fold, and it stays close
  // on needle triangles, where the thesis' form was off by a mesh size.
  kEdgeRotations,
  // Each vertex's differential coordinate by its own rotation, R_v·δ_v (the
  // thesis' rotated differential coordinates), for comparison.
  kVertexRotations,
};

struct DeformerOptions {
  // Performance threshold T on Σ (n_i² + c_i²) (thesis eq. 3.12): 0 = direct
  // recovery only (fastest), ∞ = whole-mesh optimisation (the quality reference).
  // The default is 0: bench/runtime_bench measures direct recovery within
  // 0.1–0.4% RMS of the whole-mesh result on real meshes, and finite T buys
  // little of the rest for its cost (docs/performance.md, "Runtime speed and quality").
  double threshold = kDefaultThreshold;
  RotationMethod rotation = RotationMethod::kBestFit;
  RegionTerms region_terms = RegionTerms::kEdgeRotations;
  // A time budget for a frame's region optimisation instead of a fixed T
  // (milliseconds; 0: off): after a frame whose regions took over 125% or
  // under 80% of it, T is scaled by the budget over that time (at most ×2
  // or ÷2, within [kMinBudgetT, kMaxBudgetT]), so later frames spend about
  // that, and a cut can settle. `threshold` is where
  // it starts (a finite T > 0; 0 starts at 1e4); T = ∞ has no budget.
  double regions_budget_ms = 0.0;
  static constexpr double kMinBudgetT = 100.0, kMaxBudgetT = 1e9, kBudgetStartT = 1e4;
  // Local–global refinements (as-rigid-as-possible: re-fit each rotation to
  // its ring on the result, solve again with edge terms); each lowers the
  // ARAP energy of the edges at the regions, or leaves it. Off by default.
  int local_global_iterations = 0;
  int threads = 1;
  // Let the cut follow the deformation between frames (thesis §3.3); off pins it.
  bool update_cut = true;
  // Per-frame work of the cut update: nodes rescored and nodes moved; 0 picks
  // max(2048, nodes/32) and max(128, nodes/256).
  std::size_t cut_eval_budget = 0;
  std::size_t cut_move_budget = 0;

  static constexpr double kInfinity = std::numeric_limits<double>::infinity();
  static constexpr double kDefaultThreshold = 0.0;
};

// What one deform() call did and how long each stage took.
struct FrameStats {
  std::size_t cut_nodes = 0;     // recovered nodes
  std::size_t cut_vertices = 0;  // vertices placed by direct recovery or the pose
  std::size_t regions = 0;
  std::vector<std::size_t> region_sizes;  // descending
  std::size_t region_vertices = 0;        // vertices placed by optimisation
  double threshold = 0.0;                 // the T option
  double performance_estimate = 0.0;      // T = Σ (n_i² + c_i²) of this frame's regions
  std::size_t cut_moves = 0;              // nodes the cut update moved before this frame
  // The cut has settled on this pose (AdaptiveCut::converged): more frames
  // of it change nothing. Always true at T = 0 and T = ∞.
  bool cut_converged = true;
  std::size_t factorizations = 0;         // new sparse Cholesky factorisations
  double rotations_ms = 0, cut_update_ms = 0, recover_ms = 0, regions_ms = 0, total_ms = 0;
};

struct DeformResult {
  std::vector<Vec3> positions;  // every original vertex, in original order
  FrameStats stats;
};

// One deformation stream (a session): the per-mesh data lives in a shared
// DeformerModel; a Deformer holds only its own state (recovery scratch, and
// for T > 0 the cut, the region factorisations and the last frame). Not
// thread-safe: one deform() at a time per Deformer; many Deformers may share
// a model across threads.
class Deformer {
 public:
  // Throws std::invalid_argument on bad options or a null model.
  Deformer(std::shared_ptr<const DeformerModel> model, const DeformerOptions& options = {});
  // A deformer with a model of its own; `h` must outlive it.
  Deformer(const Hierarchy& h, const DeformerOptions& options = {});
  ~Deformer();
  Deformer(const Deformer&) = delete;
  Deformer& operator=(const Deformer&) = delete;

  // Writes every original vertex's position, in original order, into `out`
  // (the caller's buffer, reused frame after frame: no allocation in the
  // steady state at T = 0). Throws PoseError (wrong length, NaN/Inf) or
  // std::invalid_argument (out.size() is not the vertex count) without
  // changing any state.
  FrameStats deform(const Pose& pose, std::span<Vec3> out);
  // The same into a new vector (tests, tools).
  DeformResult deform(const Pose& pose);

  // Changes T live; the cut adapts over the next frames (0 and ∞ take effect at once).
  void set_threshold(double threshold);
  // The adaptive cut as the last frame left it (empty unless 0 < T < ∞), and
  // back: restore_cut() takes a snapshot made by another deformer of the same
  // model after its frame of pose P; the next deform() then uses that cut as
  // it stands (that frame's cut update already happened), so deforming P
  // again gives that frame, and the frames after it follow as they would
  // have there. Throws std::invalid_argument for a snapshot of another mesh
  // (the cut is then the full one); does nothing without an adaptive T.
  CutSnapshot cut_snapshot() const;
  void restore_cut(const CutSnapshot& snapshot);
  // Threads for the next frames (≥ 1; results do not depend on it).
  void set_threads(int threads);
  const DeformerOptions& options() const { return options_; }
  std::size_t base_vertex_count() const;
  std::size_t vertex_count() const;
  // Per-vertex region id of the last frame (kNone for cut vertices), for
  // overlays; empty when every vertex is in the cut (T = 0).
  const std::vector<Index>& region_of_vertex() const;
  // The cut of the last frame (its alive faces are the cut mesh), for overlays.
  const CutState& cut_state() const;
  const DeformerModel& model() const { return *model_; }
  // Heap bytes this deformer holds of its own (not the shared model).
  std::size_t memory_bytes() const;

 private:
  struct State;
  struct Optimised;
  Optimised& optimised();
  // The vertices whose rotations edge terms read (s.fitted): the region
  // vertices and their neighbours (each rotation depends on its vertex
  // alone, so their order changes no result).
  void collect_fitted(Optimised& s) const;
  // Solves the regions with edge terms of the rotations in s.fit; returns
  // the factorisations made.
  std::size_t solve_edge_terms(Optimised& s, std::vector<Vec3>& x) const;
  // Local–global iterations on the regions of `s`, from the result `x`.
  void local_global(Optimised& s, std::vector<Vec3>& x) const;

  std::shared_ptr<const DeformerModel> model_;
  DeformerOptions options_;
  std::unique_ptr<State> s_;
};

}  // namespace filigree
