#pragma once
// A level of detail's mesh on the wire (proto DetailLevel.mesh): a Draco
// mesh, sequential encoding so the vertex order is kept, whose one attribute
// (GENERIC, 1 component, UINT32) is each vertex's original id. The ids
// ascend, so Draco's difference prediction stores their gaps.

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

// Decodes what encode_level_mesh wrote. Throws DeltaCodecError for a buffer
// that is no such mesh (not Draco, not a mesh, no UINT32 id attribute), ids
// that do not ascend or reach `vertex_limit` (the full mesh's vertex count),
// or faces that index past the level's vertices.
LevelMesh decode_level_mesh(std::string_view bytes, std::uint32_t vertex_limit);

}  // namespace filigree
