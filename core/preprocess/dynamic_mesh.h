#pragma once
// The mutable connectivity that vertex removal works on: a face table that
// only grows (faces are never renumbered, so every face keeps one id for the
// whole hierarchy) and, per vertex, its live incident faces.

#include <span>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

using FaceId = Index;

// The ordered 1-ring of a vertex: faces fan[k] = (v, ring[k], ring[k+1]),
// wrapping around when `closed`; an open ring starts and ends on the boundary.
struct VertexRing {
  std::vector<Index> ring;
  std::vector<FaceId> fan;
  bool closed = false;
};

class DynamicMesh {
 public:
  // Precondition: `mesh` is edge- and vertex-manifold with consistent orientation.
  explicit DynamicMesh(const TriMesh& mesh);

  const std::vector<Vec3>& positions() const { return positions_; }
  const Triangle& face(FaceId f) const { return faces_[f]; }
  std::size_t face_count_ever() const { return faces_.size(); }
  bool face_alive(FaceId f) const { return alive_[f]; }
  std::span<const FaceId> vertex_faces(Index v) const { return incident_[v]; }
  bool is_boundary(Index v) const { return boundary_[v]; }
  // Number of neighbouring vertices (faces, plus one on the boundary).
  std::size_t valence(Index v) const { return incident_[v].size() + (boundary_[v] ? 1 : 0); }

  // True if some live face has the edge {a, b}.
  bool has_edge(Index a, Index b) const;

  // Fills `out` with v's ordered ring; false if v has no faces or its faces
  // do not form one fan.
  bool ring(Index v, VertexRing& out) const;

  FaceId add_face(const Triangle& t);
  void kill_face(FaceId f);

  const std::vector<Triangle>& faces() const { return faces_; }

 private:
  std::vector<Vec3> positions_;
  std::vector<Triangle> faces_;
  std::vector<bool> alive_;
  std::vector<std::vector<FaceId>> incident_;
  std::vector<bool> boundary_;
};

}  // namespace filigree
