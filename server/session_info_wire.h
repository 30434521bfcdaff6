#pragma once
// SessionInfo on the wire for JoinSession and SetOptions, with the mesh's
// bytes serialized once per mesh. Before, every JoinSession of the 435k
// dragon copied the rest mesh into its response (60–73 ms, holding the
// session's lock, in freshly faulted memory) and gRPC serialized that copy
// (56–66 ms): 14 MB each time, on one of gRPC's few callback threads.
//
// The message goes out as slices: the session's own fields followed by the
// tag and length of `rest`; the mesh's shared body of `rest` (vertex count,
// positions, faces); the session's uploaded_ids, inside that same `rest`;
// and the mesh's shared `base` field. Parsers take fields in any order, and
// `rest` occurs once (JavaScript's protobuf parsers replace a message field
// that occurs twice rather than merge it).

#include <cstdint>
#include <span>

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/slice.h>

#include "filigree/v1/filigree.pb.h"

namespace filigree::server {

// A mesh's share of every SessionInfo: immutable, read by any thread.
class MeshWire {
 public:
  // `rest` must not carry uploaded_ids (they are each session's own).
  // Throws std::invalid_argument if it does, or if a part is over 2 GiB.
  MeshWire(const v1::BaseMesh& base, const v1::RestMesh& rest);

  const grpc::Slice& base_field() const { return base_field_; }  // SessionInfo.base: tag, length, message
  const grpc::Slice& rest_body() const { return rest_body_; }    // RestMesh's fields, no tag or length
  // RestMesh's fields when its arrays go in parts: vertex_count, in_parts, face_count.
  const grpc::Slice& rest_summary() const { return rest_summary_; }

 private:
  grpc::Slice base_field_, rest_body_, rest_summary_;
};

// RestMesh.uploaded_ids (field 4, packed) as wire bytes: empty for no ids.
grpc::Slice uploaded_ids_field(std::span<const std::uint32_t> ids);

// The wire bytes of `own` (a SessionInfo with neither base nor rest set:
// std::invalid_argument otherwise) with the mesh's base, and its rest
// carrying `ids` (from uploaded_ids_field); or, when the rest with its ids
// is over `inline_rest_most` bytes, the rest's summary (RestMesh.in_parts).
// Shares the mesh's bytes.
grpc::ByteBuffer session_info_wire(const v1::SessionInfo& own, const MeshWire& mesh, const grpc::Slice& ids,
                                   std::size_t inline_rest_most);

}  // namespace filigree::server
