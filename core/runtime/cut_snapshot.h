#pragma once
// What an adaptive cut (runtime/cut.h) needs to continue elsewhere exactly as
// it would have here: a session moved to another process must not restart its
// cut from the full one, or its next frames would differ from the ones the
// old process would have computed (the cut adapts a few hundred nodes a frame
// and remembers its scores; it is not a function of the current pose).

#include <cstddef>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct CutSnapshot {
  // Nodes handed to region optimisation, ascending. The cut starts full and
  // Σ n_i² ≤ T bounds the region vertices, so this list stays short.
  std::vector<Index> unrecovered;
  // Every node's acuteness at its last scoring (0 before the first): the
  // queues' order, hence the next moves, depend on all of them.
  std::vector<float> scores;
  // Where the round-robin rescoring continues.
  std::size_t next_block = 0;

  // No adaptive cut (T = 0 or ∞: the cut is then a function of T alone).
  bool empty() const { return scores.empty(); }
};

}  // namespace filigree
