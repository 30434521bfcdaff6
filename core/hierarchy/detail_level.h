#pragma once
// Levels of detail from the hierarchy: the mesh of the cut that recovers the
// first nodes of recovery_order (parents first, coarse to fine), the base
// plus one vertex a node. Every vertex of a level is a vertex of the full
// mesh (thesis §3.1.1), so a level's frame is the full frame's positions of
// its vertices.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hierarchy/hierarchy.h"

namespace filigree {

class NodeGraph;

// The level a budget of `max_vertices` (≥ 1) gets on a mesh of `vertices`
// with a base of `base_vertices`: its vertex count. Budgets round down to a
// power of two so that few levels serve many budgets; below the base they
// get the base, at or above the mesh the full mesh.
std::uint32_t detail_level_vertices(std::size_t max_vertices, std::size_t base_vertices, std::size_t vertices);

struct DetailLevelMesh {
  std::vector<Index> original_ids;  // ascending
  std::vector<Triangle> faces;      // indices into original_ids
};

// The mesh of the level with `vertices` vertices (from
// detail_level_vertices, below the full mesh). O(faces of the hierarchy).
DetailLevelMesh detail_level_mesh(const NodeGraph& graph, std::size_t vertices);

}  // namespace filigree
