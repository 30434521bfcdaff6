#pragma once
// The simplification hierarchy: everything the runtime needs to go from a
// pose of the base mesh to the detailed mesh (DESIGN §2.1, thesis §3.1–3.2).
// Plain arrays (structure of arrays) so that it (de)serialises by memcpy and
// many of them fit in one server.

#include <cstdint>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

using NodeId = Index;
using FaceId = Index;
inline constexpr Index kNone = std::numeric_limits<Index>::max();

// How the hierarchy was built (stored in the file, shown by `inspect`).
struct BuildInfo {
  std::uint64_t requested_base_vertices = 0;
  double build_seconds = 0.0;
  std::uint32_t threads = 1;
};

struct Hierarchy {
  // ---- The original mesh (rest pose), in input order.
  std::vector<Vec3> rest_positions;  // n
  // Every face that ever existed: [0, original_face_count) is the original
  // mesh, in input order; later faces were created by removals, in order.
  std::vector<Triangle> faces;
  Index original_face_count = 0;

  // ---- Nodes. Node k is the k-th vertex removal. A node's parents were
  // removed after it (they deleted faces it created) and must be recovered
  // before it; its children were removed before it.
  std::vector<Index> node_vertex;         // removed vertex (original id)
  std::vector<std::uint8_t> node_closed;  // 1: interior vertex, closed ring; 0: boundary, open ring
  // Removal-time 1-ring, ordered so that (v, ring[k], ring[k+1]) were faces.
  std::vector<Index> ring_offsets;        // N+1
  std::vector<Index> ring_vertices;
  std::vector<double> ring_weights;       // normalised, > 0 (geometry/ring_weights.h)
  // v's position in the RingFrame of its ring (geometry/ring_frame.h): direct
  // recovery puts v back at frame.from_local(node_offset) (thesis eq. 3.10).
  std::vector<Vec3> node_offset;
  // Faces deleted by the removal (v's fan; they return on recovery) and the
  // faces it created (the hole's triangulation; they go on recovery).
  std::vector<Index> removed_face_offsets;  // N+1
  std::vector<FaceId> removed_faces;
  std::vector<Index> created_face_offsets;  // N+1
  std::vector<FaceId> created_faces;
  // Dependency edges (thesis Fig. 3.9): parents[k] deleted a face that k created.
  std::vector<Index> parent_offsets;  // N+1
  std::vector<NodeId> parents;
  std::vector<Index> child_offsets;  // N+1
  std::vector<NodeId> children;

  // ---- Base mesh: the vertices never removed and the faces alive at the end.
  std::vector<Index> base_vertices;  // original ids, ascending; base order = this order
  std::vector<FaceId> base_faces;    // ids into `faces`, ascending

  // ---- MAPS parameterisation (thesis §3.1.2): vertex i lies at
  // Σ_c maps_bary[i][c] · x(faces[base_faces[maps_face[i]]][c]) on the base mesh.
  std::vector<Index> maps_face;
  std::vector<Vec3> maps_bary;

  // ---- Differential coordinates: δ_i = (L x)_i with the clamped cotangent
  // Laplacian L of the original mesh (geometry/cotangent_laplacian.h).
  std::vector<Vec3> laplacian;

  // ---- Per vertex: the node that removed it, kNone for base vertices.
  std::vector<NodeId> vertex_node;

  std::uint64_t mesh_hash = 0;  // hash_mesh() of the mesh it was built from
  BuildInfo build;

  std::size_t vertex_count() const { return rest_positions.size(); }
  std::size_t node_count() const { return node_vertex.size(); }
  std::span<const Index> ring(NodeId k) const { return span_of(ring_vertices, ring_offsets, k); }
  std::span<const double> weights(NodeId k) const {
    return {ring_weights.data() + ring_offsets[k], ring_offsets[k + 1] - ring_offsets[k]};
  }
  std::span<const FaceId> removed_faces_of(NodeId k) const { return span_of(removed_faces, removed_face_offsets, k); }
  std::span<const FaceId> created_faces_of(NodeId k) const { return span_of(created_faces, created_face_offsets, k); }
  std::span<const NodeId> parents_of(NodeId k) const { return span_of(parents, parent_offsets, k); }
  std::span<const NodeId> children_of(NodeId k) const { return span_of(children, child_offsets, k); }

  // The original mesh.
  TriMesh original_mesh() const;
  // The base mesh in base order (vertex i of it is original vertex base_vertices[i]).
  TriMesh base_mesh() const;
  // Position of vertex i through the MAPS parameterisation on the base mesh
  // whose vertices (original ids) are at `positions`.
  Vec3 maps_position(Index i, const std::vector<Vec3>& positions) const;
  // Longest chain of dependent nodes (0 for no nodes).
  std::size_t depth() const;

 private:
  static std::span<const Index> span_of(const std::vector<Index>& data, const std::vector<Index>& offsets, NodeId k) {
    return {data.data() + offsets[k], offsets[k + 1] - offsets[k]};
  }
};

// A structurally inconsistent hierarchy (bad file, or a bug); what() says what.
struct HierarchyError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Checks every invariant a consumer relies on (sizes, index ranges, finite
// values, dependency order, each face created and removed at most once, base
// consistent with the removals); throws HierarchyError naming the first
// violation. Linear time.
void validate_hierarchy(const Hierarchy& h);

}  // namespace filigree
