#include "hierarchy/hierarchy.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace filigree {
namespace {

[[noreturn]] void fail(const std::string& what) { throw HierarchyError("invalid hierarchy: " + what); }

template <class T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

void check_offsets(const std::vector<Index>& offsets, std::size_t nodes, std::size_t data, const char* name) {
  if (offsets.size() != nodes + 1) fail(std::string(name) + " offsets: " + str(offsets.size()) + " entries for " + str(nodes) + " nodes");
  if (offsets.front() != 0 || offsets.back() != data) fail(std::string(name) + " offsets do not span their data");
  for (std::size_t k = 0; k < nodes; ++k)
    if (offsets[k] > offsets[k + 1]) fail(std::string(name) + " offsets decrease at node " + str(k));
}

bool finite(const Vec3& v) { return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z()); }

}  // namespace

TriMesh Hierarchy::original_mesh() const {
  TriMesh m;
  m.positions = rest_positions;
  m.faces.assign(faces.begin(), faces.begin() + original_face_count);
  return m;
}

TriMesh Hierarchy::base_mesh() const {
  std::vector<Index> local(rest_positions.size(), kNone);
  TriMesh m;
  for (Index i = 0; i < base_vertices.size(); ++i) {
    local[base_vertices[i]] = i;
    m.positions.push_back(rest_positions[base_vertices[i]]);
  }
  for (FaceId f : base_faces) m.faces.push_back({local[faces[f][0]], local[faces[f][1]], local[faces[f][2]]});
  return m;
}

Vec3 Hierarchy::maps_position(Index i, const std::vector<Vec3>& positions) const {
  const Triangle& t = faces[base_faces[maps_face[i]]];
  const Vec3& b = maps_bary[i];
  return b[0] * positions[t[0]] + b[1] * positions[t[1]] + b[2] * positions[t[2]];
}

std::size_t Hierarchy::depth() const {
  std::vector<std::size_t> d(node_count(), 1);
  std::size_t deepest = 0;
  for (std::size_t k = node_count(); k-- > 0;) {
    for (NodeId p : parents_of(static_cast<NodeId>(k))) d[k] = std::max(d[k], d[p] + 1);
    deepest = std::max(deepest, d[k]);
  }
  return deepest;
}

void validate_hierarchy(const Hierarchy& h) {
  const std::size_t n = h.rest_positions.size();
  const std::size_t nodes = h.node_vertex.size();
  const std::size_t face_total = h.faces.size();
  if (n == 0) fail("no vertices");
  for (std::size_t i = 0; i < n; ++i)
    if (!finite(h.rest_positions[i])) fail("vertex " + str(i) + " has a non-finite coordinate");
  if (h.original_face_count == 0 || h.original_face_count > face_total) fail("original face count " + str(h.original_face_count) + " out of range");
  for (std::size_t f = 0; f < face_total; ++f)
    for (Index v : h.faces[f])
      if (v >= n) fail("face " + str(f) + " has vertex " + str(v) + " >= " + str(n));

  if (h.node_closed.size() != nodes || h.node_offset.size() != nodes) fail("per-node arrays differ in length");
  check_offsets(h.ring_offsets, nodes, h.ring_vertices.size(), "ring");
  if (h.ring_weights.size() != h.ring_vertices.size()) fail("ring weights and ring vertices differ in length");
  check_offsets(h.removed_face_offsets, nodes, h.removed_faces.size(), "removed face");
  check_offsets(h.created_face_offsets, nodes, h.created_faces.size(), "created face");
  check_offsets(h.parent_offsets, nodes, h.parents.size(), "parent");
  check_offsets(h.child_offsets, nodes, h.children.size(), "child");
  if (h.vertex_node.size() != n || h.maps_face.size() != n || h.maps_bary.size() != n || h.laplacian.size() != n)
    fail("per-vertex arrays do not have one entry per vertex");

  // Nodes and vertices correspond one to one.
  for (std::size_t k = 0; k < nodes; ++k) {
    const Index v = h.node_vertex[k];
    if (v >= n || h.vertex_node[v] != k) fail("node " + str(k) + " and its vertex disagree");
    const auto ring = h.ring(static_cast<NodeId>(k));
    const auto w = h.weights(static_cast<NodeId>(k));
    if (ring.size() < 3) fail("node " + str(k) + " has a ring of " + str(ring.size()) + " vertices");
    for (std::size_t j = 0; j < ring.size(); ++j) {
      if (ring[j] >= n || ring[j] == v) fail("node " + str(k) + " has an invalid ring vertex");
      if (!std::isfinite(w[j]) || !(w[j] > 0.0)) fail("node " + str(k) + " has a non-positive or non-finite ring weight");
    }
    if (!finite(h.node_offset[k])) fail("node " + str(k) + " has a non-finite offset");
  }
  std::size_t base_count = 0;
  for (std::size_t v = 0; v < n; ++v) {
    if (h.vertex_node[v] == kNone) {
      ++base_count;
    } else if (h.vertex_node[v] >= nodes || h.node_vertex[h.vertex_node[v]] != v) {
      fail("vertex " + str(v) + " names a node that did not remove it");
    }
  }

  // Faces: each created by at most one node (every non-original face by
  // exactly one), removed by at most one, and only after it was created.
  std::vector<NodeId> creator(face_total, kNone), remover(face_total, kNone);
  for (std::size_t k = 0; k < nodes; ++k) {
    for (FaceId f : h.created_faces_of(static_cast<NodeId>(k))) {
      if (f >= face_total || f < h.original_face_count || creator[f] != kNone) fail("node " + str(k) + " creates an invalid face " + str(f));
      creator[f] = static_cast<NodeId>(k);
    }
  }
  for (std::size_t f = h.original_face_count; f < face_total; ++f)
    if (creator[f] == kNone) fail("face " + str(f) + " was created by no node");
  std::vector<NodeId> kids;  // reused: one allocation, not one per node
  for (std::size_t k = 0; k < nodes; ++k) {
    kids.clear();
    for (FaceId f : h.removed_faces_of(static_cast<NodeId>(k))) {
      if (f >= face_total || remover[f] != kNone) fail("node " + str(k) + " removes an invalid face " + str(f));
      if (creator[f] != kNone && creator[f] >= k) fail("node " + str(k) + " removes face " + str(f) + " before it exists");
      remover[f] = static_cast<NodeId>(k);
      if (creator[f] != kNone) kids.push_back(creator[f]);
    }
    std::sort(kids.begin(), kids.end());
    kids.erase(std::unique(kids.begin(), kids.end()), kids.end());
    const auto listed = h.children_of(static_cast<NodeId>(k));
    if (!std::equal(kids.begin(), kids.end(), listed.begin(), listed.end())) fail("node " + str(k) + " lists the wrong children");
  }
  // Parents are exactly the inverse of children.
  std::vector<std::size_t> parent_count(nodes, 0);
  for (std::size_t k = 0; k < nodes; ++k) {
    for (NodeId p : h.parents_of(static_cast<NodeId>(k))) {
      if (p >= nodes || p <= k) fail("node " + str(k) + " has parent " + str(p) + " removed before it");
      const auto c = h.children_of(p);
      if (!std::binary_search(c.begin(), c.end(), static_cast<NodeId>(k))) fail("node " + str(k) + " names parent " + str(p) + " which does not name it");
    }
    parent_count[k] = h.parents_of(static_cast<NodeId>(k)).size();
  }
  std::vector<std::size_t> child_refs(nodes, 0);
  for (NodeId c : h.children) ++child_refs[c];
  if (child_refs != parent_count) fail("parent and child lists disagree");

  // Base mesh: exactly the never-removed vertices and faces.
  if (h.base_vertices.size() != base_count) fail("base vertex count does not match the removals");
  for (std::size_t i = 0; i < h.base_vertices.size(); ++i) {
    const Index v = h.base_vertices[i];
    if (v >= n || h.vertex_node[v] != kNone || (i > 0 && h.base_vertices[i - 1] >= v)) fail("base vertex " + str(i) + " is invalid");
  }
  std::size_t surviving = 0;
  for (std::size_t f = 0; f < face_total; ++f) surviving += remover[f] == kNone ? 1 : 0;
  if (h.base_faces.size() != surviving) fail("base face count does not match the removals");
  for (std::size_t i = 0; i < h.base_faces.size(); ++i) {
    const FaceId f = h.base_faces[i];
    if (f >= face_total || remover[f] != kNone || (i > 0 && h.base_faces[i - 1] >= f)) fail("base face " + str(i) + " is invalid");
  }

  for (std::size_t v = 0; v < n; ++v) {
    if (h.maps_face[v] >= h.base_faces.size()) fail("vertex " + str(v) + " is parameterised in a face outside the base mesh");
    const Vec3& b = h.maps_bary[v];
    if (!finite(b) || b.minCoeff() < -1e-9 || std::abs(b.sum() - 1.0) > 1e-6) fail("vertex " + str(v) + " has invalid barycentric coordinates");
    if (!finite(h.laplacian[v])) fail("vertex " + str(v) + " has a non-finite differential coordinate");
  }
}

}  // namespace filigree
