#pragma once
// The mutable connectivity that vertex removal works on: a face table that
// only grows (faces are never renumbered, so every face keeps one id for the
// whole hierarchy) and, per vertex, its live incident faces. Removals whose
// closed 1-rings are disjoint touch disjoint state, so they may run on
// several threads at once once their new faces' ids are reserved
// (reserve_faces, then set_face and kill_face).

#include <cstdint>
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
  // Precondition: `mesh` is edge- and vertex-manifold with consistent
  // orientation, and outlives this (its positions are read, not copied);
  // `boundary` is boundary_vertices(mesh).
  DynamicMesh(const TriMesh& mesh, std::vector<std::uint8_t> boundary);

  std::span<const Vec3> positions() const { return positions_; }
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
  // Room for `total` faces ever, so that growing the table never holds two copies.
  void reserve(std::size_t total) {
    faces_.reserve(total);
    alive_.reserve(total);
  }
  // Appends `count` dead faces and returns the first one's id; set_face then
  // makes each alive. Not thread-safe.
  FaceId reserve_faces(std::size_t count);
  // Makes reserved face f the triangle t. Safe beside calls on faces none of
  // whose vertices are t's.
  void set_face(FaceId f, const Triangle& t);
  // Safe beside calls on faces that share no vertex with f.
  void kill_face(FaceId f);

  const std::vector<Triangle>& faces() const { return faces_; }

 private:
  std::span<const Vec3> positions_;
  std::vector<Triangle> faces_;
  std::vector<std::uint8_t> alive_;  // bytes, not vector<bool>: written from several threads
  std::vector<std::vector<FaceId>> incident_;
  std::vector<std::uint8_t> boundary_;
};

}  // namespace filigree
