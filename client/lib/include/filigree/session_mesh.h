#pragma once
// What a client needs to hold to use a session: the base mesh it poses and
// the rest mesh frames are deltas from (decoded from v1::SessionInfo).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

struct SessionMesh {
  std::string session_id;
  std::string mesh_hash;  // 16 hex digits
  // The base mesh, in base order: poses give one position per base vertex.
  std::vector<float> base_positions;              // 3·m, x y z interleaved, at rest
  std::vector<std::uint32_t> base_faces;          // 3·f, indices into the base vertices
  std::vector<std::uint32_t> base_original_ids;  // m: base vertex i is original vertex base_original_ids[i]
  // The detailed rest mesh, in original order: frames are deltas from it.
  std::vector<float> rest_positions;         // 3·n
  std::vector<std::uint32_t> rest_faces;     // 3·F
  std::vector<std::uint32_t> uploaded_ids;   // empty, or n: vertex i is vertex uploaded_ids[i] of the upload
  std::uint32_t quantization_bits = 14;
  std::uint64_t version = 0;  // version of the session's frame when this was read
  v1::SessionOptions options;
  // The skeleton of a skinned upload (joints and clips), empty otherwise:
  // what Driver::send_joints() poses and Client::play_clip() plays.
  v1::Skeleton skeleton;
  // What the token it was joined with may do (JoinSession tells it); a
  // session created here: ROLE_EDITOR.
  v1::Role role = v1::ROLE_UNSPECIFIED;

  std::size_t vertex_count() const { return rest_positions.size() / 3; }
  std::size_t base_vertex_count() const { return base_positions.size() / 3; }
};

// Copies `info` into a SessionMesh after checking that its arrays agree
// (lengths multiple of 3, ids and face indices in range). Throws ClientError
// with code DATA_LOSS saying what is inconsistent.
SessionMesh to_session_mesh(const v1::SessionInfo& info);

}  // namespace filigree
