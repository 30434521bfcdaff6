#include "server/level_geometry.h"

#include "codec/level_mesh_codec.h"
#include "hierarchy/detail_level.h"
#include "hierarchy/hierarchy.h"
#include "runtime/deformer_model.h"

namespace filigree::server {

std::shared_ptr<const LevelGeometry> LevelGeometries::find(std::uint32_t vertices) const {
  std::lock_guard lock(mutex_);
  const auto it = levels_.find(vertices);
  return it == levels_.end() ? nullptr : it->second;
}

std::shared_ptr<const LevelGeometry> LevelGeometries::get(std::uint32_t vertices) {
  if (auto built = find(vertices)) return built;
  std::lock_guard building(build_mutex_);
  if (auto built = find(vertices)) return built;  // built while this call waited
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
  std::lock_guard lock(mutex_);
  levels_.emplace(vertices, g);
  return g;
}

std::size_t LevelGeometries::built() const {
  std::lock_guard lock(mutex_);
  return levels_.size();
}

}  // namespace filigree::server
