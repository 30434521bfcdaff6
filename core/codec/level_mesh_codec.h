#pragma once
// A level of detail's mesh on the wire (proto DetailLevel.mesh): a Draco
// mesh, Edgebreaker (0.8 bytes a face), whose one attribute (POSITION, 1
// component, UINT32) is each point's original id. Edgebreaker reorders
// points and faces; the level's vertex order, the order of its frames'
// deltas, is ascending original id, which the decoder restores.

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace filigree {

struct LevelMesh {
  std::vector<std::uint32_t> original_ids;  // per level vertex, ascending
  std::vector<std::uint32_t> faces;         // 3 per triangle, indices into original_ids
};

// Encodes `mesh`. Preconditions: faces.size() is a multiple of 3 and every
// index is below original_ids.size(). Throws DeltaCodecError if Draco fails.
std::string encode_level_mesh(const LevelMesh& mesh);

// Decodes what encode_level_mesh wrote: the distinct ids ascending (Draco
// may split a vertex into points with one id), faces remapped to them, in
// Draco's order with their orientation kept. Throws DeltaCodecError for a
// buffer that is no such mesh (not Draco, not a mesh, no UINT32 id
// attribute), or an id at or past `vertex_limit` (the full mesh's vertex
// count). Callers check the vertex count against DetailLevel.vertex_count.
LevelMesh decode_level_mesh(std::string_view bytes, std::uint32_t vertex_limit);

}  // namespace filigree
