#include "hierarchy/detail_level.h"

#include <bit>
#include <stdexcept>
#include <string>

#include "hierarchy/cut_state.h"
#include "hierarchy/node_graph.h"

namespace filigree {

std::uint32_t detail_level_vertices(std::size_t max_vertices, std::size_t base_vertices, std::size_t vertices) {
  if (max_vertices == 0) throw std::invalid_argument("a level of detail needs a budget of at least 1 vertex");
  if (max_vertices >= vertices) return static_cast<std::uint32_t>(vertices);
  const std::size_t level = std::bit_floor(max_vertices);
  return static_cast<std::uint32_t>(level <= base_vertices ? base_vertices : level);
}

DetailLevelMesh detail_level_mesh(const NodeGraph& graph, std::size_t vertices) {
  const Hierarchy& h = graph.hierarchy();
  const std::size_t base = h.base_vertices.size();
  if (vertices < base || vertices > h.vertex_count())
    throw std::invalid_argument("a level of " + std::to_string(vertices) + " vertices is outside [" + std::to_string(base) +
                                ", " + std::to_string(h.vertex_count()) + "]");
  CutState cut(graph);
  const std::vector<NodeId> order = recovery_order(h);
  for (std::size_t i = 0; i < vertices - base; ++i) cut.recover(order[i]);
  DetailLevelMesh out;
  const TriMesh mesh = cut.mesh(&out.original_ids);
  out.faces = mesh.faces;
  return out;
}

}  // namespace filigree
