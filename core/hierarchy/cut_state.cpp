#include "hierarchy/cut_state.h"

#include <stdexcept>
#include <string>

namespace filigree {

CutState::CutState(const Hierarchy& h)
    : h_(&h), recovered_(h.node_count(), false), missing_parents_(h.node_count()),
      recovered_children_(h.node_count(), 0), face_alive_(h.faces.size(), false) {
  for (NodeId k = 0; k < h.node_count(); ++k) missing_parents_[k] = static_cast<Index>(h.parents_of(k).size());
  for (FaceId f : h.base_faces) face_alive_[f] = true;
  alive_faces_ = h.base_faces.size();
}

void CutState::recover(NodeId k) {
  if (!can_recover(k)) throw std::logic_error("node " + std::to_string(k) + " cannot be recovered: already recovered or a parent is not");
  for (FaceId f : h_->created_faces_of(k)) face_alive_[f] = false;
  for (FaceId f : h_->removed_faces_of(k)) face_alive_[f] = true;
  alive_faces_ += h_->removed_faces_of(k).size() - h_->created_faces_of(k).size();
  recovered_[k] = true;
  ++recovered_count_;
  for (NodeId c : h_->children_of(k)) --missing_parents_[c];
  for (NodeId p : h_->parents_of(k)) ++recovered_children_[p];
}

void CutState::remove(NodeId k) {
  if (!can_remove(k)) throw std::logic_error("node " + std::to_string(k) + " cannot be removed: not recovered or a child is");
  for (FaceId f : h_->removed_faces_of(k)) face_alive_[f] = false;
  for (FaceId f : h_->created_faces_of(k)) face_alive_[f] = true;
  alive_faces_ -= h_->removed_faces_of(k).size() - h_->created_faces_of(k).size();
  recovered_[k] = false;
  --recovered_count_;
  for (NodeId c : h_->children_of(k)) ++missing_parents_[c];
  for (NodeId p : h_->parents_of(k)) --recovered_children_[p];
}

bool CutState::vertex_present(Index v) const {
  const NodeId k = h_->vertex_node[v];
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
  for (FaceId f = 0; f < h_->faces.size(); ++f) {
    if (!face_alive_[f]) continue;
    const Triangle& t = h_->faces[f];
    m.faces.push_back({local[t[0]], local[t[1]], local[t[2]]});
  }
  return m;
}

std::vector<NodeId> recovery_order(const Hierarchy& h) {
  std::vector<NodeId> order(h.node_count());
  for (NodeId k = 0; k < order.size(); ++k) order[k] = static_cast<NodeId>(order.size() - 1 - k);
  return order;
}

}  // namespace filigree
