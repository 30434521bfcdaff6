#include "filigree/session_mesh.h"

#include "filigree/client_error.h"

namespace filigree {
namespace {

[[noreturn]] void bad(const std::string& what) {
  throw ClientError(grpc::StatusCode::DATA_LOSS, "session info from the server is inconsistent: " + what);
}

template <class T>
std::vector<T> copy(const google::protobuf::RepeatedField<T>& field) {
  return {field.begin(), field.end()};
}

void check_indices(const std::vector<std::uint32_t>& indices, std::size_t limit, const char* what) {
  for (const std::uint32_t i : indices)
    if (i >= limit) bad(std::string(what) + " holds index " + std::to_string(i) + ", not below " + std::to_string(limit));
}

}  // namespace

SessionMesh to_session_mesh(const v1::SessionInfo& info) {
  SessionMesh m;
  m.session_id = info.session_id();
  m.mesh_hash = info.mesh_hash();
  m.base_positions = copy(info.base().positions());
  m.base_faces = copy(info.base().faces());
  m.base_original_ids = copy(info.base().original_ids());
  m.rest_positions = copy(info.rest().positions());
  m.rest_faces = copy(info.rest().faces());
  m.uploaded_ids = copy(info.rest().uploaded_ids());
  m.options = info.options();
  m.skeleton = info.skeleton();
  m.role = info.role();
  m.quantization_bits = info.options().quantization_bits() != 0 ? info.options().quantization_bits() : 14;
  m.version = info.version();

  if (m.base_positions.size() % 3 != 0) bad("base positions are not a multiple of 3");
  if (m.base_faces.size() % 3 != 0) bad("base faces are not a multiple of 3");
  if (m.rest_positions.size() % 3 != 0) bad("rest positions are not a multiple of 3");
  if (m.rest_faces.size() % 3 != 0) bad("rest faces are not a multiple of 3");
  if (m.vertex_count() != info.rest().vertex_count())
    bad("rest vertex_count " + std::to_string(info.rest().vertex_count()) + " but " +
        std::to_string(m.vertex_count()) + " positions");
  if (m.base_original_ids.size() != m.base_vertex_count())
    bad(std::to_string(m.base_original_ids.size()) + " original ids for " + std::to_string(m.base_vertex_count()) +
        " base vertices");
  if (!m.uploaded_ids.empty() && m.uploaded_ids.size() != m.vertex_count())
    bad(std::to_string(m.uploaded_ids.size()) + " uploaded ids for " + std::to_string(m.vertex_count()) + " vertices");
  check_indices(m.base_faces, m.base_vertex_count(), "base faces");
  check_indices(m.base_original_ids, m.vertex_count(), "base original ids");
  check_indices(m.rest_faces, m.vertex_count(), "rest faces");
  return m;
}

}  // namespace filigree
