#pragma once
// What a changing cut needs beyond the stored hierarchy, derived from it once
// per mesh (runtime/deformer_model.h shares it): which faces each removal
// deleted, and the dependency edges between nodes (thesis Fig. 3.9). Node
// k's children created faces that k deleted; its parents deleted faces k
// created, and must be recovered before it.
//
// Not stored in the hierarchy (≈ 50 bytes per vertex): direct recovery
// (T = 0) needs none of it.

#include <span>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace filigree {

class NodeGraph {
 public:
  // Derives the graph of `h`, which must pass validate_hierarchy() and
  // outlive it. O(faces). Checks what validation leaves to it: every fan
  // slot of every node holds exactly one face that was alive then, and no
  // face is deleted twice; throws HierarchyError naming the first violation.
  // `threads`: 0 uses two for a large hierarchy; the result never depends on it.
  explicit NodeGraph(const Hierarchy& h, std::size_t threads = 0);

  const Hierarchy& hierarchy() const { return *h_; }
  // The node that removed vertex v; kNone for a base vertex.
  NodeId node_of_vertex(Index v) const { return vertex_node_[v]; }
  // The faces node k deleted, slot i holding fan_face(k, i) (up to rotation).
  std::span<const FaceId> removed_faces_of(NodeId k) const {
    return {removed_faces_.data() + h_->ring_offsets[k], h_->fan_size(k)};
  }
  // Ascending.
  std::span<const NodeId> children_of(NodeId k) const { return span_of(children_, child_offsets_, k); }
  std::span<const NodeId> parents_of(NodeId k) const { return span_of(parents_, parent_offsets_, k); }
  // Heap bytes held.
  std::size_t memory_bytes() const;

 private:
  static std::span<const NodeId> span_of(const std::vector<NodeId>& data, const std::vector<Index>& offsets, NodeId k) {
    return {data.data() + offsets[k], offsets[k + 1] - offsets[k]};
  }

  const Hierarchy* h_;
  std::vector<NodeId> vertex_node_;
  std::vector<FaceId> removed_faces_;  // per ring slot; an open ring's last slot kNone
  std::vector<Index> child_offsets_, parent_offsets_;
  std::vector<NodeId> children_, parents_;
};

}  // namespace filigree
