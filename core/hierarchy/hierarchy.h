#pragma once
// The simplification hierarchy: everything the runtime needs to go from a
// pose of the base mesh to the detailed mesh (DESIGN §2.1, thesis §3.1–3.2).
// Plain arrays (structure of arrays) so that it (de)serialises by memcpy and
// many of them fit in one server. The stored ones are MappedArrays: a
// hierarchy loaded from a file reads them in place from the mapped file
// (load_hierarchy), one built or deserialised in memory owns them.
//
// Compact (format v3, issue 10): 32-bit indices, float32 or 16-bit fixed
// point wherever the value is relative to a local frame (see each field for
// why that is precise enough), faces created by removals as 3-byte ring
// corners, and nothing stored that the rest determines. The base mesh
// (base_vertices, base_faces) is derived when a file is loaded. What only a
// changing cut needs (which face each removal deleted, the dependency edges)
// is derived by whoever needs it (hierarchy/node_graph.h), and vertex → node
// by vertex_nodes(): direct recovery (T = 0) needs only the latter, once,
// while it lays itself out.
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"
#include "util/mapped_array.h"

namespace filigree {

using NodeId = Index;
using FaceId = Index;
using Vec3f = Eigen::Vector3f;
inline constexpr Index kNone = std::numeric_limits<Index>::max();

// A face created by a removal, as the positions of its corners in the
// removed vertex's ring (the hole's triangulation only joins ring vertices):
// how the file stores created faces, in 3 bytes instead of 12.
using RingCorners = std::array<std::uint8_t, 3>;

// Barycentric coordinates (b0, b1, 1 − b0 − b1) in a triangle, b0 and b1
// as multiples of 1/65535 with b0 + b1 ≤ 65535.
using Barycentric16 = std::array<std::uint16_t, 2>;
inline constexpr double kFixedPointOne = 65535.0;
// So a ring has at most this many vertices (preprocessing stops at 32).
inline constexpr std::size_t kMaxRingSize = 255;

// Consecutive face ids [first, last): iterable, indexable. (Not
// std::ranges::iota_view: the fuzzing build's clang cannot compile
// libstdc++ 12's ranges.)
struct FaceIdRange {
  struct iterator {
    FaceId f;
    FaceId operator*() const { return f; }
    iterator& operator++() { return ++f, *this; }
    bool operator==(const iterator&) const = default;
  };
  FaceId first = 0, last = 0;
  iterator begin() const { return {first}; }
  iterator end() const { return {last}; }
  std::size_t size() const { return last - first; }
  FaceId operator[](std::size_t i) const { return static_cast<FaceId>(first + i); }
};

// How the hierarchy was built. Only what was asked is stored in the file
// (shown by `inspect`): the time and the thread count are not, so that one
// mesh with one set of options gives the same file byte for byte however it
// was built (a loaded hierarchy has 0 for both).
struct BuildInfo {
  std::uint64_t requested_base_vertices = 0;
  double build_seconds = 0.0;
  std::uint32_t threads = 1;
};

struct Hierarchy {
  // ---- The original mesh (rest pose), in input order. Double: the identity
  // pose must give back the rest mesh within 1e-9 of the bbox diagonal.
  MappedArray<Vec3> rest_positions;  // n
  // Every face that ever existed, numbered: [0, original_face_count()) the
  // original mesh in input order, then the faces created by removals, in
  // order (face()). Only the original ones are stored as triangles.
  MappedArray<Triangle> original_faces;

  // ---- Nodes. Node k is the k-th vertex removal. Its ring vertices were
  // removed after it (or never), so they are recovered before it.
  MappedArray<Index> node_vertex;         // removed vertex (original id)
  MappedArray<std::uint8_t> node_closed;  // 1: interior vertex, closed ring; 0: boundary, open ring
  // Removal-time 1-ring, ordered so that (v, ring[k], ring[k+1]) were faces.
  MappedArray<Index> ring_offsets;        // N+1
  MappedArray<Index> ring_vertices;
  // Relative weights in 16-bit fixed point, each ≥ 1: w_i = ring_weights[i] / Σ
  // (geometry/ring_weights.h, then quantize_ring_weights(); Σ is 65535 up to
  // a step per weight). Enough because
  // preprocessing rounds the weights *before* it computes node_offset: the
  // offset is exact for the stored weights, and ring_frame() divides by
  // their sum, so the rounding only changes which (equally valid) centre the
  // offset is relative to.
  MappedArray<std::uint16_t> ring_weights;
  // v's position in the RingFrame of its ring (geometry/ring_frame.h): direct
  // recovery puts v back at frame.from_local(node_offset) (thesis eq. 3.10).
  // Float32: the offset is rotation- and scale-free, O(1), so rounding moves
  // v by ~1e-7 of its ring's radius; the rest pose stays exact because direct
  // recovery adds back its float error of the rest pose.
  MappedArray<Vec3f> node_offset;
  // The removal deleted v's fan: face (v, ring[i], ring[i+1]) for each ring
  // slot i (fan_face()), one fewer for an open ring. Which face ids those
  // are is derived (NodeGraph::removed_faces_of).
  // Faces created by the removal (the hole's triangulation; they go on
  // recovery), as corners in its ring: a ring of r vertices leaves a hole of
  // r corners, so node k created exactly r − 2 faces, ids
  // original_face_count() + ring_offsets[k] − 2k onwards (created_faces_of),
  // stored here at index ring_offsets[k] − 2k onwards. 3 bytes a face
  // instead of a 12-byte triangle.
  MappedArray<RingCorners> created_corners;

  // ---- Base mesh: the vertices never removed and the faces alive at the end
  // (derived).
  std::vector<Index> base_vertices;  // original ids, ascending; base order = this order
  std::vector<FaceId> base_faces;    // face ids, ascending

  // ---- MAPS parameterisation (thesis §3.1.2): vertex i lies at
  // Σ_c b_c · x(face(base_faces[maps_face[i]])[c]) on the base mesh, b =
  // maps_barycentric(i).
  // The first two barycentrics in 16-bit fixed point (maps_barycentric());
  // rounding moves the point by ~1e-5 of its base triangle, far below the
  // parameterisation's own distortion.
  MappedArray<Index> maps_face;
  MappedArray<Barycentric16> maps_bary;

  std::uint64_t mesh_hash = 0;  // hash_mesh() of the mesh it was built from
  BuildInfo build;

  std::size_t vertex_count() const { return rest_positions.size(); }
  std::size_t node_count() const { return node_vertex.size(); }
  std::size_t ring_size(NodeId k) const { return ring_offsets[k + 1] - ring_offsets[k]; }
  std::span<const Index> ring(NodeId k) const { return {ring_vertices.data() + ring_offsets[k], ring_size(k)}; }
  std::span<const std::uint16_t> weights(NodeId k) const { return {ring_weights.data() + ring_offsets[k], ring_size(k)}; }
  // The number of faces node k deleted: its ring's edges.
  std::size_t fan_size(NodeId k) const { return ring_size(k) - (node_closed[k] ? 0 : 1); }
  // Ids of the faces node k created, ascending.
  FaceIdRange created_faces_of(NodeId k) const {
    const FaceId first = first_created_face(k);
    return {first, static_cast<FaceId>(first + ring_size(k) - 2)};
  }
  FaceId first_created_face(NodeId k) const {
    return static_cast<FaceId>(original_faces.size() + ring_offsets[k] - 2 * std::size_t{k});
  }
  std::size_t original_face_count() const { return original_faces.size(); }
  std::size_t face_count() const { return original_faces.size() + created_corners.size(); }
  // The j-th face node k created (j < ring_size(k) − 2).
  Triangle created_face(NodeId k, std::size_t j) const {
    const RingCorners& c = created_corners[ring_offsets[k] - 2 * std::size_t{k} + j];
    const Index* r = ring_vertices.data() + ring_offsets[k];
    return {r[c[0]], r[c[1]], r[c[2]]};
  }
  // The face in slot i of node k's fan (i < fan_size(k)), (v, ring[i],
  // ring[i+1]): the deleted face's corners up to rotation.
  Triangle fan_face(NodeId k, std::size_t i) const {
    const auto r = ring(k);
    return {node_vertex[k], r[i], r[i + 1 == r.size() ? 0 : i + 1]};
  }
  // The node that created face f, kNone for an original face; O(log nodes).
  NodeId creator(FaceId f) const;
  // Any face: O(1) for an original face, O(log nodes) for a created one.
  // To visit every face, for_each_face() is linear.
  Triangle face(FaceId f) const;
  // Calls fn(f, face(f)) for every face, ascending.
  template <class Fn>
  void for_each_face(Fn&& fn) const {
    FaceId f = 0;
    for (const Triangle& t : original_faces) fn(f++, t);
    for (NodeId k = 0; k < node_count(); ++k)
      for (std::size_t j = 0; j + 2 < ring_size(k); ++j) fn(f++, created_face(k, j));
  }
  // The original mesh.
  TriMesh original_mesh() const;
  // The base mesh in base order (vertex i of it is original vertex base_vertices[i]).
  TriMesh base_mesh() const;
  // Vertex i's barycentrics in base face maps_face[i].
  Vec3 maps_barycentric(Index i) const;
  // Position of vertex i through the MAPS parameterisation on the base mesh
  // whose vertices (original ids) are at `positions`.
  Vec3 maps_position(Index i, std::span<const Vec3> positions) const;
  // Longest chain of dependent nodes (0 for no nodes): node k depends on the
  // nodes that removed its ring vertices.
  std::size_t depth() const;
  // Heap bytes held: the capacities of every array.
  std::size_t memory_bytes() const;

};

// Per vertex, the node that removed it; kNone for a base vertex. O(n).
std::vector<NodeId> vertex_nodes(const Hierarchy& h);

// Calls fn(p) for each node p whose vertex is in node k's ring (repeats
// possible): what direct recovery of k reads, all with ids above k.
// `node_of` is vertex_nodes(h).
template <class Fn>
void for_each_ring_dependency(const Hierarchy& h, const std::vector<NodeId>& node_of, NodeId k, Fn&& fn) {
  for (Index u : h.ring(k))
    if (node_of[u] != kNone) fn(node_of[u]);
}

// Normalised positive weights (geometry/ring_weights.h) in 16-bit fixed
// point, each ≥ 1: what Hierarchy::ring_weights stores.
std::vector<std::uint16_t> quantize_ring_weights(std::span<const double> weights);
std::uint16_t quantize_ring_weight(double w);
// A barycentric triple (≥ 0, Σ = 1) as Hierarchy::maps_bary stores it.
Barycentric16 quantize_barycentric(const Vec3& b);

// The arrays a hierarchy is made of, as read-only views: exactly what the
// file stores (hierarchy_file.h), laid out as in a Hierarchy. Everything else
// is derived from these.
struct StoredHierarchy {
  std::span<const Vec3> rest_positions;
  std::span<const Triangle> original_faces;
  std::span<const RingCorners> created_corners;  // per created face, in face order
  std::span<const Index> node_vertex;
  std::span<const std::uint8_t> node_closed;
  std::span<const Index> ring_offsets;
  std::span<const Index> ring_vertices;
  std::span<const std::uint16_t> ring_weights;
  std::span<const Vec3f> node_offset;
  std::span<const Index> maps_face;
  std::span<const Barycentric16> maps_bary;
};

// A structurally inconsistent hierarchy (bad file, or a bug); what() says what.
struct HierarchyError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Checks every invariant direct recovery and the base mesh rely on (sizes,
// index ranges, finite values, each vertex removed at most once, every ring
// vertex present after its node's removal, created faces inside their ring,
// as many faces left at the end as the removals leave); throws
// HierarchyError naming the first violation. Linear time, in sequential
// passes (random reads only into per-vertex bit sets). That each removal
// deleted exactly its fan's faces is checked where it is used, by
// NodeGraph (node_graph.h).
void validate_hierarchy(const StoredHierarchy& s);

// Validates `s` and builds the hierarchy from it: its arrays viewed in place
// if `storage` is given (it keeps the memory `s` points into alive for as
// long as any array views it), copied otherwise; the derived ones (the base
// mesh) computed. mesh_hash, build and nothing else are left to the caller.
// `concurrently` (if any) is called once, alongside the checks: on a helper
// thread for a large hierarchy on a machine with a second core (the file
// loader computes the payload's checksum there). Throws HierarchyError.
Hierarchy hierarchy_from(const StoredHierarchy& s, const std::shared_ptr<const void>& storage = {},
                         const std::function<void()>& concurrently = {});

// The stored view of `h` (its arrays, no copy). Throws HierarchyError if the
// ring offsets are not valid.
StoredHierarchy stored_view(const Hierarchy& h);

// validate_hierarchy(stored_view(h)), then checks that every derived array
// equals its derivation.
void validate_hierarchy(const Hierarchy& h);

}  // namespace filigree
