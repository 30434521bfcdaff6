#pragma once
// Checking an input mesh and repairing what can be repaired.

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// One kind of problem: how many times it occurs and the first offending index
// (a vertex or face index, as named by the kind; -1 when count is 0).
struct IssueCount {
  std::size_t count = 0;
  std::int64_t first = -1;
  void add(std::int64_t index) {
    if (count++ == 0) first = index;
  }
};

// The most faces one vertex may be in. A polygon of many corners,
// fan-triangulated by a writer, puts one vertex in all its triangles: the
// simplifier's work at such a vertex grows with the square of their number
// (an 80,000-corner polygon took 18 s; a 16,384-corner one 1.4 s).
inline constexpr std::size_t kMaxFacesAtVertex = 8192;

// What validate_mesh() found. Vertex/face indices refer to the mesh as given.
struct ValidationReport {
  std::size_t vertex_count = 0;
  std::size_t face_count = 0;
  IssueCount non_finite_vertices;      // vertex index; NaN or Inf coordinate
  IssueCount out_of_range_faces;       // face index; an index >= vertex_count
  IssueCount degenerate_faces;         // face index; a repeated vertex index
  IssueCount zero_area_faces;          // face index; distinct indices, area ~ 0 (kept)
  IssueCount duplicate_faces;          // face index of the later copy (same vertex set)
  IssueCount unreferenced_vertices;    // vertex index
  IssueCount non_manifold_edges;       // face index of a face on an edge with > 2 faces
  IssueCount non_manifold_vertices;    // vertex index whose faces form several fans
  IssueCount inconsistent_orientation; // face index; an edge used twice in one direction
  IssueCount crowded_vertices;         // vertex index; in more than kMaxFacesAtVertex faces
  std::size_t components = 0;          // connected components (by shared vertices)
  std::size_t boundary_loops = 0;
  std::size_t boundary_edges = 0;

  // True when repair cannot make the mesh usable: empty, NaN/Inf, bad
  // indices, non-manifold, inconsistent orientation.
  bool fatal() const;
  // Problems that repair_mesh() removes.
  bool repairable() const;
  // A multi-line human-readable summary, one line per non-zero item.
  std::string to_string() const;
};

// Inspects the mesh; never throws, never modifies it.
ValidationReport validate_mesh(const TriMesh& mesh);

struct RepairOptions {
  // Merge vertices whose positions are within weld_tolerance (absolute units);
  // off by default because it changes the vertex count and order.
  bool weld_coincident = false;
  double weld_tolerance = 0.0;
};

// What repair_mesh() changed, and how the vertex order maps.
struct RepairReport {
  std::size_t removed_degenerate_faces = 0;
  std::size_t removed_duplicate_faces = 0;
  std::size_t removed_unreferenced_vertices = 0;
  std::size_t welded_vertices = 0;
  // new vertex index -> index in the mesh as given (identity if nothing changed).
  std::vector<Index> new_to_old_vertex;
  // new face index -> index in the mesh as given.
  std::vector<Index> new_to_old_face;
  bool changed() const;
  std::string to_string() const;
};

// Thrown when a mesh cannot be used; what() says why, with counts and first
// offending index.
struct InvalidMeshError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Removes degenerate and duplicate faces and unreferenced vertices (optionally
// welds), then validates again. Throws InvalidMeshError if the result is still
// unusable: empty, NaN/Inf coordinates, out-of-range indices, non-manifold
// edges or vertices, inconsistent orientation.
TriMesh repair_mesh(const TriMesh& mesh, const RepairOptions& options, RepairReport* report);

}  // namespace filigree
