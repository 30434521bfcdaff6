#pragma once
// Vertex orders with spatial locality: neighbours in space become neighbours
// in memory and on the wire, which helps caches and delta compression.

#include <span>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// A permutation (new index → old index) sorting vertices along a Morton
// (Z-order) curve over the bounding box, 21 bits per axis; ties keep the old
// order, so the result depends only on the positions.
std::vector<Index> locality_order(std::span<const Vec3> positions);

// The mesh with vertex i of the result being vertex new_to_old[i] of `mesh`;
// faces keep their order and corner order. Precondition: new_to_old is a
// permutation of [0, vertex_count).
TriMesh permute_vertices(const TriMesh& mesh, const std::vector<Index>& new_to_old);

}  // namespace filigree
