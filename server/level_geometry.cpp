#include "server/level_geometry.h"

#include "codec/level_mesh_codec.h"
#include "hierarchy/detail_level.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer_model.h"

namespace filigree::server {

std::shared_ptr<const LevelGeometry> LevelGeometries::get(std::uint32_t vertices) {
  std::lock_guard lock(mutex_);
  if (const auto it = levels_.find(vertices); it != levels_.end()) return it->second;
  const DetailLevelMesh level = detail_level_mesh(model_.node_graph(), vertices);
  auto g = std::make_shared<LevelGeometry>();
  g->vertex_count = static_cast<std::uint32_t>(level.original_ids.size());
  g->face_count = static_cast<std::uint32_t>(level.faces.size());
  g->original_ids = level.original_ids;
  const Hierarchy& h = model_.hierarchy();
  g->rest.reserve(level.original_ids.size());
  for (Index v : level.original_ids) g->rest.push_back(h.rest_positions[v]);
  LevelMesh wire;
  wire.original_ids.assign(level.original_ids.begin(), level.original_ids.end());
  wire.faces.reserve(3 * level.faces.size());
  for (const Triangle& t : level.faces) wire.faces.insert(wire.faces.end(), t.begin(), t.end());
  g->mesh = encode_level_mesh(wire);
  levels_.emplace(vertices, g);
  return g;
}

std::size_t LevelGeometries::built() const {
  std::lock_guard lock(mutex_);
  return levels_.size();
}

}  // namespace filigree::server
