#pragma once
// The adaptive cut (thesis §3.3): which nodes are directly recovered and
// which vertices are left to region optimisation, moved a little every frame
// so that optimisation goes where the deformation is acute while the
// performance estimate T = Σ (n_i² + c_i²) stays under a threshold.

#include <limits>
#include <utility>
#include <vector>

#include "hierarchy/cut_state.h"
#include "runtime/cut_snapshot.h"
#include "runtime/node_heap.h"
#include "runtime/regions.h"

namespace filigree {

struct CotangentLaplacian;

class AdaptiveCut {
 public:
  static constexpr double kInfinity = std::numeric_limits<double>::infinity();

  // `graph` (and its hierarchy) and `laplacian` (of the original mesh) must
  // outlive the cut. Starts as reset(threshold) leaves it.
  AdaptiveCut(const NodeGraph& graph, const CotangentLaplacian& laplacian, double threshold = kInfinity);
  AdaptiveCut(const AdaptiveCut&) = delete;  // the queues point into it
  AdaptiveCut& operator=(const AdaptiveCut&) = delete;

  // T = 0: every node recovered (direct recovery only); T = ∞: none (one
  // region per component: whole-mesh optimisation). Otherwise the cut starts
  // full and update() hands the most acutely deformed nodes to regions.
  // O(n); only a finite T > 0 holds per-node queue state.
  void reset(double threshold);
  // Changes T keeping the cut (it adapts over the next updates); 0 and ∞, or
  // leaving them, reset.
  void set_threshold(double threshold);
  double threshold() const { return threshold_; }

  // Rescores the nodes of `eval_budget` vertices (rounded up to whole blocks
  // of kScoreBlock) on `positions`, the last frame's result, round robin, on
  // up to `threads` threads (the scores do not depend on it). The round
  // robin visits blocks of consecutive vertices spread over the whole mesh
  // (see kPhases): a session's vertices are in spatial order, so what
  // scoring reads lies close in memory, and each frame still samples the
  // whole mesh, as a round robin in node order did.
  // Then moves up to `move_budget` nodes: while the estimate exceeds T it
  // recovers the mildest nodes (without limit: T is a bound); then it
  // un-recovers the most acute node while it fits, or, when it does not,
  // pairs that with recovering the mildest node (the thesis' pair move) if
  // the swap fits and clearly improves the acuteness optimised. Regions are
  // brought up to date when anything moved, searching again only those the
  // moves touched. Returns the nodes moved (a move undone is none).
  std::size_t update(const std::vector<Vec3>& positions, std::size_t eval_budget, std::size_t move_budget,
                     int threads = 1);

  // The state update() continues from (empty unless 0 < T < ∞), and back:
  // restore() makes this cut the snapshot's, with the queues and regions it
  // implies, so that the next update() moves what the snapshot's cut would
  // have moved on the same positions. A snapshot of another mesh, or of an
  // invalid cut, throws std::invalid_argument and leaves the cut as reset()
  // does; without an adaptive T (or with an empty snapshot) it does nothing.
  CutSnapshot snapshot() const;
  void restore(const CutSnapshot& snapshot);

  // Whether the cut has settled for the positions it is given: every node
  // scored since its last move, none moved (a full round of the scoring's
  // round robin). Always true at T = 0 and T = ∞. A new pose may move it again.
  bool converged() const { return !adaptive() || scored_since_move_ >= h_.vertex_count(); }

  const CutState& state() const { return cut_; }
  const Regions& regions() const { return regions_; }
  const std::vector<bool>& in_cut() const { return in_cut_; }
  // Deformation acuteness of node k at its last scoring (stretch + normal
  // difference of its triangles on the cut mesh); 0 before its first.
  double score(NodeId k) const { return score_.empty() ? 0.0 : score_[k]; }
  // Heap bytes held (cut, regions, queues, scores).
  std::size_t memory_bytes() const;

 private:
  // Queue orders: the mildest node first, resp. the most acute; ties go to
  // the lower node id, so the moves depend only on the scores.
  struct Milder {
    bool operator()(const HeapEntry& a, const HeapEntry& b) const {
      return a.key != b.key ? a.key < b.key : a.node < b.node;
    }
  };
  struct MoreAcute {
    bool operator()(const HeapEntry& a, const HeapEntry& b) const {
      return a.key != b.key ? a.key > b.key : a.node < b.node;
    }
  };
  // Vertex → union-find id for the vertices moved since the last region
  // update: open addressing, cleared at each update (a few thousand entries).
  class MovedIds {
   public:
    void set(Index v, Index id);
    Index get(Index v) const;
    void clear();
    std::size_t memory_bytes() const { return slots_.capacity() * sizeof(slots_[0]); }

   private:
    std::size_t find(Index v) const;
    std::vector<std::pair<Index, Index>> slots_;  // (vertex, id), vertex kNone if empty
    std::size_t used_ = 0;
  };

  bool adaptive() const { return threshold_ > 0.0 && threshold_ < kInfinity; }
  // Acuteness of node k (its vertex v) on positions x, −1 off the frontier.
  double evaluate(NodeId k, Index v, const std::vector<Vec3>& x) const;
  // Scoring goes by blocks of this many consecutive vertices, visited in the
  // order (b mod kPhases, b div kPhases): a budget of 1/kPhases of the
  // vertices takes every kPhases-th block, all over the mesh.
  static constexpr std::size_t kScoreBlock = 64;
  static constexpr std::size_t kPhases = 32;
  // The first vertex of the block at position `ordinal` of the visiting order.
  std::size_t block_at(std::size_t ordinal) const;
  // Scores the nodes of vertices first … first + count − 1 (count ≤
  // kScoreBlock) into out, −1 for base vertices and nodes off the frontier.
  void score_block(std::size_t first, std::size_t count, const std::vector<Vec3>& x, float* out) const;
  // Puts node k in the queue its state calls for (recoverable, removable or
  // neither) at its current score.
  void place(NodeId k);
  void place_around(NodeId k);
  void recover(NodeId k);
  void unrecover(NodeId k);
  void note_change(Index v);
  // Incremental estimate of T: union-find over the regions of the last exact
  // computation, with sizes n and constraint counts c per root. It errs high:
  // a recovery is assumed not to split its region and to add a constraint, an
  // un-recovery to add every cut neighbour as a new constraint. Exact values
  // return when regions are brought up to date.
  Index region_root(Index v);
  double delta_unrecover(NodeId k);
  void rebuild_regions();
  // The union-find estimate from regions_ as they stand (exact).
  void sync_estimate();
  void release_queues();

  const Hierarchy& h_;
  const NodeGraph& graph_;
  const CotangentLaplacian& laplacian_;
  double threshold_ = kInfinity;
  CutState cut_;
  std::vector<bool> in_cut_;
  Regions regions_;
  // Finite T only (empty otherwise). Scores are heuristics: float is plenty.
  std::vector<float> score_;
  std::vector<Index> place_;  // node → slot in whichever queue holds it
  NodeHeap<Milder> recoverable_;
  NodeHeap<MoreAcute> removable_;
  std::size_t next_block_ = 0;  // position in the scoring order
  std::size_t scored_since_move_ = 0;  // vertices whose nodes were scored since the cut last moved
  double estimate_ = 0.0;
  std::vector<Index> uf_parent_;
  std::vector<double> uf_size_, uf_constraints_;
  // Vertices moved since regions were last brought up to date: regions_ still
  // describes the cut before them, so a moved vertex's union-find id is kept
  // aside (kNone while it is in the cut).
  std::vector<Index> changed_;
  std::vector<bool> moved_;
  MovedIds moved_id_;
};

}  // namespace filigree
