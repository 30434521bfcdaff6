#include "filigree/decoded_level.h"

#include <string>

#include "codec/delta_codec.h"
#include "codec/level_mesh_codec.h"
#include "filigree/client_error.h"

namespace filigree {
namespace {

[[noreturn]] void bad(const v1::DetailLevel& level, const std::string& what) {
  throw ClientError(grpc::StatusCode::DATA_LOSS,
                    "level of " + std::to_string(level.vertex_count()) + " vertices: " + what);
}

}  // namespace

DecodedLevel decode_level(const v1::DetailLevel& level, std::span<const float> rest_positions) {
  const std::size_t n = rest_positions.size() / 3;
  DecodedLevel out;
  out.vertex_count = level.vertex_count();
  out.face_count = level.face_count();
  out.stream_id = level.stream_id();
  if (level.vertex_count() == 0) bad(level, "a level has at least the base's vertices");
  if (level.vertex_count() > n) bad(level, "the mesh has only " + std::to_string(n));
  if (level.mesh().empty()) {
    // Full detail: the rest mesh itself.
    if (level.vertex_count() != n)
      bad(level, "no mesh, which only the full mesh's level (" + std::to_string(n) + " vertices) may omit");
    out.full_detail = true;
    return out;
  }
  LevelMesh mesh;
  try {
    mesh = decode_level_mesh(level.mesh(), static_cast<std::uint32_t>(n));
  } catch (const DeltaCodecError& e) {
    bad(level, e.what());
  }
  if (mesh.original_ids.size() != level.vertex_count())
    bad(level, "its mesh has " + std::to_string(mesh.original_ids.size()) + " vertices");
  if (mesh.faces.size() != 3 * std::size_t{level.face_count()})
    bad(level, "its mesh has " + std::to_string(mesh.faces.size() / 3) + " faces, not " +
                   std::to_string(level.face_count()));
  out.original_ids = std::move(mesh.original_ids);
  out.faces = std::move(mesh.faces);
  out.rest_positions.resize(3 * out.original_ids.size());
  for (std::size_t i = 0; i < out.original_ids.size(); ++i)
    for (std::size_t c = 0; c < 3; ++c) out.rest_positions[3 * i + c] = rest_positions[3 * out.original_ids[i] + c];
  return out;
}

}  // namespace filigree
