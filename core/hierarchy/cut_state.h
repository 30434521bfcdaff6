#pragma once
// A cut of the hierarchy (thesis §3.1.1): the set of recovered nodes, closed
// under "a recovered node's parents are recovered", and the cut mesh it
// defines. The empty cut is the base mesh, the full cut the original mesh.

#include <vector>

#include "hierarchy/hierarchy.h"
#include "hierarchy/node_graph.h"

namespace filigree {

class CutState {
 public:
  // Starts at the empty cut (the base mesh). `graph` (and its hierarchy)
  // must outlive the CutState.
  explicit CutState(const NodeGraph& graph);
  // The full cut (the original mesh) in O(n), without recovering node by
  // node. Without `graph` it can be read but not changed: recover() and
  // remove() throw std::logic_error, can_recover() and can_remove() are
  // false.
  static CutState full(const Hierarchy& h, const NodeGraph* graph = nullptr);

  bool recovered(NodeId k) const { return recovered_[k]; }
  // Not recovered and every parent recovered.
  bool can_recover(NodeId k) const {
    if (recovered_[k]) return false;
    return blockers_.empty() ? parents_recovered(k) : blockers_[k] == 0;
  }
  // Recovered and no child recovered.
  bool can_remove(NodeId k) const {
    if (!recovered_[k] || !g_) return false;
    return blockers_.empty() ? !child_recovered(k) : blockers_[k] == 0;
  }

  // Puts node k's vertex back: its created faces go, its fan returns.
  // Throws std::logic_error unless can_recover(k).
  void recover(NodeId k);
  // The inverse: removes k's vertex again. Throws unless can_remove(k).
  void remove(NodeId k);

  std::size_t recovered_count() const { return recovered_count_; }
  // A base vertex, or the vertex of a recovered node.
  bool vertex_present(Index v) const;
  bool face_alive(FaceId f) const { return face_alive_[f]; }
  std::size_t alive_face_count() const { return alive_faces_; }

  // The cut mesh: present vertices in ascending original id, alive faces in
  // ascending face id. `original_ids`, if given, receives the original id of
  // each output vertex. For the full cut this is exactly the original mesh.
  TriMesh mesh(std::vector<Index>* original_ids = nullptr) const;

  // Starts loading what can_recover(k) and can_remove(k) read (callers that
  // test many scattered nodes issue these ahead).
  void prefetch(NodeId k) const {
    if (!blockers_.empty()) __builtin_prefetch(&blockers_[k]);
  }

  // Heap bytes held (a cut that never changed holds two bits per node and one
  // per face).
  std::size_t memory_bytes() const;

 private:
  CutState(const Hierarchy& h, const NodeGraph* graph);
  const NodeGraph& graph() const;  // throws std::logic_error for a read-only cut
  bool parents_recovered(NodeId k) const;
  bool child_recovered(NodeId k) const;
  void count_blockers();

  const Hierarchy* h_;
  const NodeGraph* g_;  // null: a full cut that is only read
  std::vector<bool> recovered_;
  // Per node, made on the first change (a cut that never changes, such as
  // T = 0's full one, needs none): for a recovered node its recovered
  // children, else its parents not recovered. A node changes state only when
  // this is 0, and it is 0 again after the change, so one count serves both.
  std::vector<Index> blockers_;
  std::vector<bool> face_alive_;
  std::size_t recovered_count_ = 0;
  std::size_t alive_faces_ = 0;
};

// A valid order to recover every node: descending node id (a node's parents
// were removed after it, so they come first).
std::vector<NodeId> recovery_order(const Hierarchy& h);

}  // namespace filigree
