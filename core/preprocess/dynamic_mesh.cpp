#include "preprocess/dynamic_mesh.h"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace filigree {

DynamicMesh::DynamicMesh(const TriMesh& mesh, std::vector<std::uint8_t> boundary)
    : positions_(mesh.positions), faces_(mesh.faces), alive_(mesh.faces.size(), 1), incident_(mesh.positions.size()),
      boundary_(std::move(boundary)) {
  if (boundary_.size() != positions_.size()) throw std::invalid_argument("DynamicMesh: one boundary flag per vertex");
  // Counted first: one allocation per vertex, not a growing vector's three,
  // with room for two more faces: a neighbour's removal usually adds at most
  // that, and a list that grows on a worker thread moves to that thread's
  // malloc arena (2 threads peaked 70 MiB above 1 at 1.25M vertices).
  std::vector<std::uint32_t> count(positions_.size(), 0);
  for (const Triangle& t : faces_)
    for (Index v : t) ++count[v];
  for (Index v = 0; v < positions_.size(); ++v) incident_[v].reserve(count[v] + 2);
  for (FaceId f = 0; f < faces_.size(); ++f)
    for (Index v : faces_[f]) incident_[v].push_back(f);
}

bool DynamicMesh::has_edge(Index a, Index b) const {
  // From the end with fewer faces: a fan-triangulated polygon's hub has
  // thousands, and every neighbour's removal asks about edges to it.
  if (incident_[b].size() < incident_[a].size()) std::swap(a, b);
  for (FaceId f : incident_[a]) {
    const Triangle& t = faces_[f];
    if (t[0] == b || t[1] == b || t[2] == b) return true;
  }
  return false;
}

bool DynamicMesh::ring(Index v, VertexRing& out) const {
  out.ring.clear();
  out.fan.clear();
  const auto& inc = incident_[v];
  const std::size_t n = inc.size();
  if (n == 0) return false;
  // Each face (v, a, b) links a → b; small n, so linear scans beat hashing.
  auto next_of = [&](FaceId f, Index& a, Index& b) {
    const Triangle& t = faces_[f];
    const int c = t[0] == v ? 0 : t[1] == v ? 1 : 2;
    a = t[(c + 1) % 3];
    b = t[(c + 2) % 3];
  };
  // Start: for a boundary vertex, the face whose `a` is no face's `b`.
  std::size_t start = 0;
  if (boundary_[v]) {
    start = n;
    for (std::size_t i = 0; i < n && start == n; ++i) {
      Index a, b;
      next_of(inc[i], a, b);
      bool is_target = false;
      for (std::size_t j = 0; j < n && !is_target; ++j) {
        Index a2, b2;
        next_of(inc[j], a2, b2);
        is_target = b2 == a;
      }
      if (!is_target) start = i;
    }
    if (start == n) return false;
  }
  Index a, b;
  next_of(inc[start], a, b);
  out.ring.push_back(a);
  out.fan.push_back(inc[start]);
  Index cur = b;
  while (out.fan.size() < n) {
    std::size_t found = n;
    for (std::size_t j = 0; j < n; ++j) {
      Index a2, b2;
      next_of(inc[j], a2, b2);
      if (a2 == cur) {
        found = j;
        b = b2;
        break;
      }
    }
    if (found == n) break;
    out.ring.push_back(cur);
    out.fan.push_back(inc[found]);
    cur = b;
  }
  if (out.fan.size() != n) return false;
  out.closed = !boundary_[v];
  if (out.closed) return cur == out.ring.front();
  out.ring.push_back(cur);
  return true;
}

FaceId DynamicMesh::add_face(const Triangle& t) {
  const FaceId f = reserve_faces(1);
  set_face(f, t);
  return f;
}

FaceId DynamicMesh::reserve_faces(std::size_t count) {
  const FaceId first = static_cast<FaceId>(faces_.size());
  faces_.resize(faces_.size() + count);
  alive_.resize(alive_.size() + count, 0);
  return first;
}

void DynamicMesh::set_face(FaceId f, const Triangle& t) {
  faces_[f] = t;
  alive_[f] = 1;
  for (Index v : t) incident_[v].push_back(f);
}

void DynamicMesh::kill_face(FaceId f) {
  alive_[f] = 0;
  for (Index v : faces_[f]) {
    auto& inc = incident_[v];
    inc.erase(std::find(inc.begin(), inc.end(), f));
  }
}

}  // namespace filigree
