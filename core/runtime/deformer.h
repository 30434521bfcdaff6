#pragma once
// The runtime (DESIGN §2.2): given positions for the base vertices, the
// full-resolution detail-preserving deformation, with the cut threshold T as
// the quality/speed knob. Built once from a Hierarchy, then deform() per pose.

#include <limits>
#include <memory>
#include <vector>

#include "runtime/base_rotations.h"
#include "runtime/pose.h"

namespace filigree {

struct Hierarchy;
class CutState;

struct DeformerOptions {
  // Performance threshold T on Σ (n_i² + c_i²) (thesis eq. 3.12): 0 = direct
  // recovery only (fastest), ∞ = whole-mesh optimisation (the quality reference).
  // The default is 0: bench/runtime_bench measures direct recovery within
  // 0.1–0.4% RMS of the whole-mesh result on real meshes, and finite T buys
  // little of the rest for its cost (README, "Runtime speed and quality").
  double threshold = kDefaultThreshold;
  RotationMethod rotation = RotationMethod::kBestFit;
  // Local–global refinements (re-fit per-vertex rotations on the result, solve
  // again); off by default.
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
  std::size_t factorizations = 0;         // new sparse Cholesky factorisations
  double rotations_ms = 0, cut_update_ms = 0, recover_ms = 0, regions_ms = 0, total_ms = 0;
};

struct DeformResult {
  std::vector<Vec3> positions;  // every original vertex, in original order
  FrameStats stats;
};

class Deformer {
 public:
  // `h` must outlive the deformer. Throws std::invalid_argument on bad options.
  Deformer(const Hierarchy& h, const DeformerOptions& options = {});
  ~Deformer();
  Deformer(const Deformer&) = delete;
  Deformer& operator=(const Deformer&) = delete;

  // Throws PoseError (wrong length, NaN/Inf) without changing any state.
  DeformResult deform(const Pose& pose);

  // Changes T live; the cut adapts over the next frames (0 and ∞ take effect at once).
  void set_threshold(double threshold);
  const DeformerOptions& options() const { return options_; }
  std::size_t base_vertex_count() const;
  // Per-vertex region id of the last frame (kNone for cut vertices), for overlays.
  const std::vector<Index>& region_of_vertex() const;
  // The cut of the last frame (its alive faces are the cut mesh), for overlays.
  const CutState& cut_state() const;

 private:
  struct State;
  const Hierarchy& h_;
  DeformerOptions options_;
  std::unique_ptr<State> s_;
};

}  // namespace filigree
