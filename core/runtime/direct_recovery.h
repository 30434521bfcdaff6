#pragma once
// Direct recovery of the cut vertices (thesis §3.4, eq. 3.10): each recovered
// node's vertex is put back at its stored offset in the frame of its ring,
// parents before children.

#include <vector>

#include "hierarchy/hierarchy.h"

namespace filigree {

class CutState;

class DirectRecovery {
 public:
  explicit DirectRecovery(const Hierarchy& h);

  // Places the vertex of every recovered node of `cut` in `x`; base vertices
  // must already be in `x`. Nodes are grouped by depth below the roots: a
  // node's ring vertices are base vertices or vertices of its ancestors, so
  // one depth level only reads levels above it and its nodes run in parallel.
  // Uses at most `threads` threads; the result does not depend on how many.
  void recover(const CutState& cut, std::vector<Vec3>& x, int threads) const;

  std::size_t levels() const { return level_offsets_.size() - 1; }

 private:
  // The nodes' data copied into processing order (by level, then spatially):
  // recovery streams through it
  // instead of jumping around the hierarchy's node order, which made it
  // memory-latency bound.
  // Positions are worked on in a private order too — base vertices, then the
  // nodes' vertices in processing order — so that ring loads of neighbouring
  // nodes fall on the same cache lines; `ring_` holds indices in that order.
  std::vector<Index> base_vertices_;
  std::vector<Index> level_offsets_{0};  // into the per-node arrays below
  std::vector<NodeId> node_;             // hierarchy node id
  std::vector<Index> vertex_;            // original vertex id
  std::vector<std::uint8_t> closed_;
  std::vector<Vec3> offset_;
  std::vector<Index> ring_offsets_{0};
  std::vector<Index> ring_;  // private indices
  std::vector<double> weights_;
  mutable std::vector<Vec3> work_;
};

}  // namespace filigree
