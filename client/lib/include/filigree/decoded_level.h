#pragma once
// A level of detail a stream is served at (v1::DetailLevel, the message that
// starts a level on a stream opened with a vertex budget), decoded: which
// vertices of the full mesh it keeps and the faces between them.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

struct DecodedLevel {
  // Vertices of the level: what its frames carry (DecodedFrame::positions
  // holds 3 per vertex). The full mesh's count at full detail.
  std::uint32_t vertex_count = 0;
  std::uint32_t face_count = 0;
  // The stream's id on the server, for set_detail (Watcher, Driver).
  std::uint64_t stream_id = 0;
  // The level is the full mesh: original_ids, faces and rest_positions are
  // then empty (the session's rest mesh, SessionMesh::rest_*, is the level).
  bool full_detail = false;
  // Per level vertex: the full mesh's vertex it is (session order), ascending.
  std::vector<std::uint32_t> original_ids;
  // 3 per triangle, indices into the level's vertices.
  std::vector<std::uint32_t> faces;
  // 3 per level vertex: the rest mesh's positions of original_ids. A level
  // frame's positions are these plus its deltas.
  std::vector<float> rest_positions;
};

// Decodes `level` for a session whose rest mesh is `rest_positions` (3·n
// floats). Throws ClientError (DATA_LOSS) for a level that does not fit the
// mesh: a mesh that does not decode, ids that do not ascend below n, counts
// that disagree with the mesh, or no mesh below full detail.
DecodedLevel decode_level(const v1::DetailLevel& level, std::span<const float> rest_positions);

}  // namespace filigree
