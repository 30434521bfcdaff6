#pragma once
// The adaptive cut (thesis §3.3): which nodes are directly recovered and
// which vertices are left to region optimisation, moved a little every frame
// so that optimisation goes where the deformation is acute while the
// performance estimate T = Σ (n_i² + c_i²) stays under a threshold.

#include <limits>
#include <queue>
#include <vector>

#include "hierarchy/cut_state.h"
#include "runtime/regions.h"

namespace filigree {

struct CotangentLaplacian;

class AdaptiveCut {
 public:
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  // `h` and `laplacian` (of the original mesh) must outlive the cut.
  AdaptiveCut(const Hierarchy& h, const CotangentLaplacian& laplacian);

  // T = 0: every node recovered (direct recovery only); T = ∞: none (one
  // region per component: whole-mesh optimisation). Otherwise the cut starts
  // full and update() hands the most acutely deformed nodes to regions.
  void reset(double threshold);
  // Changes T keeping the cut (it adapts over the next updates); 0 and ∞, or
  // leaving them, reset.
  void set_threshold(double threshold);
  double threshold() const { return threshold_; }

  // Rescores up to `eval_budget` nodes (round robin) on `positions`, the last
  // frame's result, then moves up to `move_budget` nodes: while the estimate
  // exceeds T it recovers the mildest nodes (without limit: T is a bound);
  // then it un-recovers the most acute node while it fits, or, when it does
  // not, pairs that with recovering the mildest node (the thesis' pair move)
  // if the swap fits and clearly improves the acuteness optimised.
  // Regions are recomputed when anything moved. Returns the nodes moved.
  std::size_t update(const std::vector<Vec3>& positions, std::size_t eval_budget, std::size_t move_budget);

  const CutState& state() const { return cut_; }
  const Regions& regions() const { return regions_; }
  const std::vector<bool>& in_cut() const { return in_cut_; }
  // Deformation acuteness of node k at its last scoring (stretch + normal
  // difference of its triangles on the cut mesh), −1 if it was not on the frontier.
  double score(NodeId k) const { return score_[k]; }

 private:
  struct Entry {
    double score;
    NodeId node;
    std::uint32_t stamp;
  };
  struct Milder {
    bool operator()(const Entry& a, const Entry& b) const { return a.score != b.score ? a.score > b.score : a.node > b.node; }
  };
  struct MoreAcute {
    bool operator()(const Entry& a, const Entry& b) const { return a.score != b.score ? a.score < b.score : a.node > b.node; }
  };

  double evaluate(NodeId k, const std::vector<Vec3>& x) const;
  void enqueue(NodeId k);
  void enqueue_neighbours(NodeId k);
  NodeId top_recoverable();
  NodeId top_removable();
  void recover(NodeId k);
  void unrecover(NodeId k);
  // Incremental estimate of T: union-find over the regions of the last exact
  // computation, with sizes n and constraint counts c per root. It errs high:
  // a recovery is assumed not to split its region and to add a constraint, an
  // un-recovery to add every cut neighbour as a new constraint. Exact values
  // return when regions are recomputed.
  Index region_root(Index v);
  double delta_unrecover(NodeId k);
  void rebuild_regions();

  const Hierarchy& h_;
  const CotangentLaplacian& laplacian_;
  double threshold_ = kInfinity;
  CutState cut_;
  std::vector<bool> in_cut_;
  Regions regions_;
  std::vector<double> score_;
  std::vector<std::uint32_t> stamp_;
  std::size_t next_eval_ = 0;
  std::priority_queue<Entry, std::vector<Entry>, Milder> recoverable_;
  std::priority_queue<Entry, std::vector<Entry>, MoreAcute> removable_;
  double estimate_ = 0.0;
  std::vector<Index> uf_parent_;
  std::vector<double> uf_size_, uf_constraints_;
  std::vector<Index> est_region_;  // per vertex: region id for the estimate, kNone in the cut
};

}  // namespace filigree
