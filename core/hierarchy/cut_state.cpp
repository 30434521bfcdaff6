#include "hierarchy/cut_state.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace filigree {

CutState::CutState(const NodeGraph& graph) : CutState(graph.hierarchy(), &graph) {}

CutState::CutState(const Hierarchy& h, const NodeGraph* graph)
    : h_(&h), g_(graph), recovered_(h.node_count(), false), face_alive_(h.face_count(), false) {
  if (graph && &graph->hierarchy() != &h) throw std::invalid_argument("a cut's node graph is another hierarchy's");
  for (FaceId f : h.base_faces) face_alive_[f] = true;
  alive_faces_ = h.base_faces.size();
}

CutState CutState::full(const Hierarchy& h, const NodeGraph* graph) {
  // Every node recovered is the original mesh: a node's recovery kills the
  // faces it created and no original face stays deleted, so the alive faces
  // are exactly the original ones (tests compare it with node-by-node recovery).
  CutState cut(h, graph);
  cut.recovered_.assign(h.node_count(), true);
  cut.recovered_count_ = h.node_count();
  cut.face_alive_.assign(h.face_count(), false);
  std::fill_n(cut.face_alive_.begin(), h.original_face_count(), true);
  cut.alive_faces_ = h.original_face_count();
  return cut;
}

const NodeGraph& CutState::graph() const {
  if (!g_) throw std::logic_error("a cut made without the hierarchy's node graph cannot change");
  return *g_;
}

bool CutState::parents_recovered(NodeId k) const {
  const auto parents = graph().parents_of(k);
  return std::all_of(parents.begin(), parents.end(), [&](NodeId p) { return recovered_[p]; });
}

bool CutState::child_recovered(NodeId k) const {
  const auto children = graph().children_of(k);
  return std::any_of(children.begin(), children.end(), [&](NodeId c) { return recovered_[c]; });
}

void CutState::count_blockers() {
  const NodeGraph& g = graph();
  blockers_.assign(h_->node_count(), 0);
  for (NodeId k = 0; k < h_->node_count(); ++k) {
    Index n = 0;
    if (recovered_[k]) {
      for (NodeId c : g.children_of(k)) n += recovered_[c] ? 1 : 0;
    } else {
      for (NodeId p : g.parents_of(k)) n += recovered_[p] ? 0 : 1;
    }
    blockers_[k] = n;
  }
}

void CutState::recover(NodeId k) {
  const NodeGraph& g = graph();  // before any change
  if (!can_recover(k)) throw std::logic_error("node " + std::to_string(k) + " cannot be recovered: already recovered or a parent is not");
  if (blockers_.empty()) count_blockers();
  for (FaceId f : h_->created_faces_of(k)) face_alive_[f] = false;
  for (FaceId f : g.removed_faces_of(k)) face_alive_[f] = true;
  alive_faces_ += g.removed_faces_of(k).size() - h_->created_faces_of(k).size();
  recovered_[k] = true;
  ++recovered_count_;
  // k's children are not recovered (k was not): one parent fewer missing.
  // k's parents are recovered: one recovered child more.
  for (NodeId c : g.children_of(k)) --blockers_[c];
  for (NodeId p : g.parents_of(k)) ++blockers_[p];
}

void CutState::remove(NodeId k) {
  const NodeGraph& g = graph();
  if (!can_remove(k)) throw std::logic_error("node " + std::to_string(k) + " cannot be removed: not recovered or a child is");
  if (blockers_.empty()) count_blockers();
  for (FaceId f : g.removed_faces_of(k)) face_alive_[f] = false;
  for (FaceId f : h_->created_faces_of(k)) face_alive_[f] = true;
  alive_faces_ -= g.removed_faces_of(k).size() - h_->created_faces_of(k).size();
  recovered_[k] = false;
  --recovered_count_;
  for (NodeId c : g.children_of(k)) ++blockers_[c];
  for (NodeId p : g.parents_of(k)) --blockers_[p];
}

bool CutState::vertex_present(Index v) const {
  if (!g_) return true;  // a read-only cut is the full one
  const NodeId k = g_->node_of_vertex(v);
  return k == kNone || recovered_[k];
}

TriMesh CutState::mesh(std::vector<Index>* original_ids) const {
  std::vector<Index> local(h_->vertex_count(), kNone);
  TriMesh m;
  if (original_ids) original_ids->clear();
  for (Index v = 0; v < h_->vertex_count(); ++v) {
    if (!vertex_present(v)) continue;
    local[v] = static_cast<Index>(m.positions.size());
    m.positions.push_back(h_->rest_positions[v]);
    if (original_ids) original_ids->push_back(v);
  }
  m.faces.reserve(alive_faces_);
  h_->for_each_face([&](FaceId f, const Triangle& t) {
    if (face_alive_[f]) m.faces.push_back({local[t[0]], local[t[1]], local[t[2]]});
  });
  return m;
}

std::size_t CutState::memory_bytes() const {
  return (recovered_.capacity() + face_alive_.capacity()) / 8 + blockers_.capacity() * sizeof(Index);
}

std::vector<NodeId> recovery_order(const Hierarchy& h) {
  std::vector<NodeId> order(h.node_count());
  for (NodeId k = 0; k < order.size(); ++k) order[k] = static_cast<NodeId>(order.size() - 1 - k);
  return order;
}

}  // namespace filigree
