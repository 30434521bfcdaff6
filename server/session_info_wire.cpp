#include "server/session_info_wire.h"

#include "server/serialized_frame.h"

#include <array>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

namespace filigree::server {
namespace {

// Wire types and tags (protobuf encoding): SessionInfo.base = 3 and .rest =
// 4, RestMesh.uploaded_ids = 4, all length-delimited.
constexpr std::uint8_t kLengthDelimited = 2;
constexpr std::uint8_t kBaseTag = (3 << 3) | kLengthDelimited;
constexpr std::uint8_t kRestTag = (4 << 3) | kLengthDelimited;
constexpr std::uint8_t kUploadedIdsTag = (4 << 3) | kLengthDelimited;

void check_size(std::size_t bytes, const char* what) {
  if (bytes > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::invalid_argument(std::string(what) + " of " + std::to_string(bytes) + " bytes is over protobuf's 2 GiB limit");
}

}  // namespace

MeshWire::MeshWire(const v1::BaseMesh& base, const v1::RestMesh& rest) {
  if (rest.uploaded_ids_size() > 0) throw std::invalid_argument("a mesh's shared rest must not carry a session's uploaded_ids");
  const std::size_t base_size = base.ByteSizeLong(), rest_size = rest.ByteSizeLong();
  check_size(base_size, "a base mesh");
  check_size(rest_size, "a rest mesh");
  std::string field(1, static_cast<char>(kBaseTag));
  append_varint(field, base_size);
  base.AppendToString(&field);
  base_field_ = owned_slice(std::move(field));
  std::string body;
  body.reserve(rest_size);
  rest.AppendToString(&body);
  rest_body_ = owned_slice(std::move(body));
  v1::RestMesh summary;
  summary.set_vertex_count(rest.vertex_count());
  summary.set_in_parts(true);
  summary.set_face_count(static_cast<std::uint32_t>(rest.faces_size() / 3));
  rest_summary_ = owned_slice(summary.SerializeAsString());
}

grpc::Slice uploaded_ids_field(std::span<const std::uint32_t> ids) {
  if (ids.empty()) return grpc::Slice();
  std::string packed;
  packed.reserve(5 * ids.size());
  for (const std::uint32_t id : ids) append_varint(packed, id);
  std::string field(1, static_cast<char>(kUploadedIdsTag));
  append_varint(field, packed.size());
  field += packed;
  check_size(field.size(), "uploaded ids");
  return owned_slice(std::move(field));
}

grpc::ByteBuffer session_info_wire(const v1::SessionInfo& own, const MeshWire& mesh, const grpc::Slice& ids,
                                   std::size_t inline_rest_most) {
  if (own.has_base() || own.has_rest()) throw std::invalid_argument("a session's own SessionInfo fields must leave base and rest to the mesh");
  std::string head;
  own.SerializeToString(&head);
  const bool in_parts = mesh.rest_body().size() + ids.size() > inline_rest_most;
  const grpc::Slice none;
  const grpc::Slice& rest = in_parts ? mesh.rest_summary() : mesh.rest_body();
  const grpc::Slice& rest_ids = in_parts ? none : ids;
  const std::size_t rest_size = rest.size() + rest_ids.size();
  check_size(rest_size, "a rest mesh with its uploaded ids");
  head.push_back(static_cast<char>(kRestTag));
  append_varint(head, rest_size);
  // Empty slices are left out: gRPC may not expect them.
  std::array<grpc::Slice, 4> slices;
  std::size_t n = 0;
  slices[n++] = grpc::Slice(head);
  for (const grpc::Slice* s : {&rest, &rest_ids, &mesh.base_field()})
    if (s->size() > 0) slices[n++] = *s;
  return grpc::ByteBuffer(slices.data(), n);
}

}  // namespace filigree::server
