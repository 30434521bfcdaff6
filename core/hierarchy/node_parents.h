#pragma once
// The dependency edges read the other way (thesis Fig. 3.9): node k's parents
// are the nodes that deleted a face k created, and must be recovered before
// it. The hierarchy stores children only; a cut that changes derives these
// once per mesh (runtime/deformer_model.h shares them).

#include <span>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace filigree {

struct NodeParents {
  std::vector<Index> offsets;  // node count + 1
  std::vector<NodeId> parents;  // per node, ascending

  std::span<const NodeId> of(NodeId k) const { return {parents.data() + offsets[k], offsets[k + 1] - offsets[k]}; }
  // Heap bytes held.
  std::size_t memory_bytes() const { return offsets.capacity() * sizeof(Index) + parents.capacity() * sizeof(NodeId); }
};

// The inverse of h's child lists, in O(nodes + edges). `h` must be valid
// (validate_hierarchy): child ids below the node count.
NodeParents node_parents(const Hierarchy& h);

}  // namespace filigree
