#pragma once
// The levels of detail of one mesh (proto DetailLevel): each level's mesh,
// built the first time a stream asks for it and shared by every session and
// stream of the mesh after.

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {
class DeformerModel;
}  // namespace filigree

namespace filigree::server {

struct LevelGeometry {
  std::uint32_t vertex_count = 0;
  std::uint32_t face_count = 0;
  std::vector<Index> original_ids;  // ascending
  std::vector<Vec3> rest;           // the rest positions of original_ids
  std::string mesh;                 // DetailLevel.mesh (level_mesh_codec.h)
};

class LevelGeometries {
 public:
  // `model` must outlive this object (both live in SessionAssets).
  explicit LevelGeometries(const DeformerModel& model) : model_(model) {}

  // The level of `vertices` vertices (detail_level_vertices' answer, below
  // the full mesh): built on the caller's thread the first time (the node
  // graph first, if no finite T built it: ~0.4 s at 1.25M), shared after.
  // Thread-safe; builds run one at a time. Throws what building throws.
  std::shared_ptr<const LevelGeometry> get(std::uint32_t vertices);
  // The level if it is built; null otherwise (never waits for a build).
  std::shared_ptr<const LevelGeometry> find(std::uint32_t vertices) const;

  // Levels built so far.
  std::size_t built() const;

 private:
  const DeformerModel& model_;
  std::mutex build_mutex_;     // held while building
  mutable std::mutex mutex_;  // guards levels_
  std::map<std::uint32_t, std::shared_ptr<const LevelGeometry>> levels_;
};

}  // namespace filigree::server
