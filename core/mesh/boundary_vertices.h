#pragma once
// Which vertices lie on the mesh's boundary.

#include <cstdint>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// Per vertex, 1 if an edge from it is used by one face only. Each vertex
// compares the next and the previous corners of its faces (on a manifold an
// interior vertex sees each neighbour once as each), on up to `threads`
// threads: a sort of all 3F edges was ~0.5 s at 1.25M vertices.
// Precondition: edge-manifold, consistently oriented, indices in range
// (validate_mesh reports nothing fatal).
std::vector<std::uint8_t> boundary_vertices(const TriMesh& mesh, int threads);

}  // namespace filigree
