// Sessions: create, join, the mesh and skeleton accessors, close, free.

#include <limits>

#include "c_api/internal.h"

namespace filigree::c_api {
namespace {

v1::SessionOptions to_options(const filigree_session_options& o) {
  v1::SessionOptions out;
  out.set_base_vertices(o.base_vertices);
  out.set_base_ratio(o.base_ratio);
  out.set_threshold(o.threshold);
  out.set_whole_mesh(o.whole_mesh != 0);
  out.set_quantization_bits(o.quantization_bits);
  if (!v1::SkinningMethod_IsValid(o.skinning))
    throw std::invalid_argument("skinning " + std::to_string(o.skinning) + " is neither 0 (linear blend) nor 1 (dual quaternion)");
  out.set_skinning(static_cast<v1::SkinningMethod>(o.skinning));
  return out;
}

// The accessors below: a handle check, then a copy of one array.
template <class T>
int copy_array(const filigree_session* session, const char* function, const std::vector<T>& (*pick)(const SessionMesh&),
               T* buffer, std::size_t capacity, std::size_t* required) {
  return with_handle(session, function, [&](const filigree_session& s) -> int {
    const std::vector<T>& v = pick(s.mesh);
    return copy_out(&s.error, function, v.data(), v.size(), sizeof(T), buffer, capacity, required);
  });
}

// An index into the joints or clips, checked.
int out_of_range(const filigree_session& s, const char* function, const char* what, std::size_t index,
                 std::size_t count) {
  return fail(&s.error, FILIGREE_OUT_OF_RANGE,
              std::string(function) + ": " + what + " " + std::to_string(index) + " of " + std::to_string(count));
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;
using filigree::SessionMesh;

extern "C" {

int filigree_create_session(filigree_client* client, const void* mesh_bytes, size_t size, const char* format,
                            const filigree_session_options* options, const char* client_name, filigree_session** out) {
  constexpr const char* kFunction = "filigree_create_session";
  return with_handle(client, kFunction, [&](filigree_client& c) -> int {
    if (!out) return null_argument(&c.error, kFunction, "out");
    *out = nullptr;
    if (!mesh_bytes && size > 0) return null_argument(&c.error, kFunction, "mesh_bytes");
    if (!format) return null_argument(&c.error, kFunction, "format");
    const filigree::v1::SessionOptions session_options = options ? to_options(*options) : filigree::v1::SessionOptions();
    filigree::SessionHandle created = c.connection->client.create_session(
        std::string(static_cast<const char*>(mesh_bytes), size), format, session_options,
        client_name ? client_name : "filigree-c");
    auto handle = std::make_unique<filigree_session>();
    handle->connection = c.connection;
    handle->editor_token = std::move(created.editor_token);
    handle->viewer_token = std::move(created.viewer_token);
    handle->token = handle->editor_token;
    handle->mesh = std::move(created.mesh);
    return hand_out(std::move(handle), out);
  });
}

int filigree_join(filigree_client* client, const char* session_id, const char* token, filigree_session** out) {
  constexpr const char* kFunction = "filigree_join";
  return with_handle(client, kFunction, [&](filigree_client& c) -> int {
    if (!out) return null_argument(&c.error, kFunction, "out");
    *out = nullptr;
    if (!session_id) return null_argument(&c.error, kFunction, "session_id");
    if (!token) return null_argument(&c.error, kFunction, "token");
    auto handle = std::make_unique<filigree_session>();
    handle->connection = c.connection;
    handle->mesh = c.connection->client.join(session_id, token);
    handle->token = token;
    return hand_out(std::move(handle), out);
  });
}

int filigree_session_id(const filigree_session* session, char* buffer, size_t capacity, size_t* required) {
  return with_handle(session, "filigree_session_id", [&](const filigree_session& s) -> int {
    return copy_string(&s.error, "filigree_session_id", s.mesh.session_id, buffer, capacity, required);
  });
}

int filigree_session_editor_token(const filigree_session* session, char* buffer, size_t capacity, size_t* required) {
  return with_handle(session, "filigree_session_editor_token", [&](const filigree_session& s) -> int {
    return copy_string(&s.error, "filigree_session_editor_token", s.editor_token, buffer, capacity, required);
  });
}

int filigree_session_viewer_token(const filigree_session* session, char* buffer, size_t capacity, size_t* required) {
  return with_handle(session, "filigree_session_viewer_token", [&](const filigree_session& s) -> int {
    return copy_string(&s.error, "filigree_session_viewer_token", s.viewer_token, buffer, capacity, required);
  });
}

int filigree_session_vertex_count(const filigree_session* session, size_t* count) {
  return with_handle(session, "filigree_session_vertex_count", [&](const filigree_session& s) -> int {
    if (!count) return null_argument(&s.error, "filigree_session_vertex_count", "count");
    *count = s.mesh.vertex_count();
    return FILIGREE_OK;
  });
}

int filigree_session_base_vertex_count(const filigree_session* session, size_t* count) {
  return with_handle(session, "filigree_session_base_vertex_count", [&](const filigree_session& s) -> int {
    if (!count) return null_argument(&s.error, "filigree_session_base_vertex_count", "count");
    *count = s.mesh.base_vertex_count();
    return FILIGREE_OK;
  });
}

int filigree_session_rest_positions(const filigree_session* session, float* buffer, size_t capacity,
                                    size_t* required) {
  return copy_array<float>(
      session, "filigree_session_rest_positions",
      [](const SessionMesh& m) -> const std::vector<float>& { return m.rest_positions; }, buffer, capacity, required);
}

int filigree_session_rest_faces(const filigree_session* session, uint32_t* buffer, size_t capacity, size_t* required) {
  return copy_array<std::uint32_t>(
      session, "filigree_session_rest_faces",
      [](const SessionMesh& m) -> const std::vector<std::uint32_t>& { return m.rest_faces; }, buffer, capacity,
      required);
}

int filigree_session_uploaded_ids(const filigree_session* session, uint32_t* buffer, size_t capacity,
                                  size_t* required) {
  return copy_array<std::uint32_t>(
      session, "filigree_session_uploaded_ids",
      [](const SessionMesh& m) -> const std::vector<std::uint32_t>& { return m.uploaded_ids; }, buffer, capacity,
      required);
}

int filigree_session_base_positions(const filigree_session* session, float* buffer, size_t capacity,
                                    size_t* required) {
  return copy_array<float>(
      session, "filigree_session_base_positions",
      [](const SessionMesh& m) -> const std::vector<float>& { return m.base_positions; }, buffer, capacity, required);
}

int filigree_session_base_faces(const filigree_session* session, uint32_t* buffer, size_t capacity, size_t* required) {
  return copy_array<std::uint32_t>(
      session, "filigree_session_base_faces",
      [](const SessionMesh& m) -> const std::vector<std::uint32_t>& { return m.base_faces; }, buffer, capacity,
      required);
}

int filigree_session_base_original_ids(const filigree_session* session, uint32_t* buffer, size_t capacity,
                                       size_t* required) {
  return copy_array<std::uint32_t>(
      session, "filigree_session_base_original_ids",
      [](const SessionMesh& m) -> const std::vector<std::uint32_t>& { return m.base_original_ids; }, buffer,
      capacity, required);
}

int filigree_session_joint_count(const filigree_session* session, size_t* count) {
  return with_handle(session, "filigree_session_joint_count", [&](const filigree_session& s) -> int {
    if (!count) return null_argument(&s.error, "filigree_session_joint_count", "count");
    *count = static_cast<std::size_t>(s.mesh.skeleton.joints_size());
    return FILIGREE_OK;
  });
}

int filigree_session_joint_name(const filigree_session* session, size_t joint, char* buffer, size_t capacity,
                                size_t* required) {
  constexpr const char* kFunction = "filigree_session_joint_name";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    const std::size_t count = static_cast<std::size_t>(s.mesh.skeleton.joints_size());
    if (joint >= count) return out_of_range(s, kFunction, "joint", joint, count);
    return copy_string(&s.error, kFunction, s.mesh.skeleton.joints(static_cast<int>(joint)).name(), buffer, capacity,
                       required);
  });
}

int filigree_session_joint_parent(const filigree_session* session, size_t joint, int32_t* parent) {
  constexpr const char* kFunction = "filigree_session_joint_parent";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    if (!parent) return null_argument(&s.error, kFunction, "parent");
    const std::size_t count = static_cast<std::size_t>(s.mesh.skeleton.joints_size());
    if (joint >= count) return out_of_range(s, kFunction, "joint", joint, count);
    *parent = s.mesh.skeleton.joints(static_cast<int>(joint)).parent();
    return FILIGREE_OK;
  });
}

int filigree_session_joint_rest(const filigree_session* session, size_t joint, float* buffer, size_t capacity,
                                size_t* required) {
  constexpr const char* kFunction = "filigree_session_joint_rest";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    const std::size_t count = static_cast<std::size_t>(s.mesh.skeleton.joints_size());
    if (joint >= count) return out_of_range(s, kFunction, "joint", joint, count);
    const auto& rest = s.mesh.skeleton.joints(static_cast<int>(joint)).rest();
    return copy_out(&s.error, kFunction, rest.data(), static_cast<std::size_t>(rest.size()), sizeof(float), buffer,
                    capacity, required);
  });
}

int filigree_session_clip_count(const filigree_session* session, size_t* count) {
  return with_handle(session, "filigree_session_clip_count", [&](const filigree_session& s) -> int {
    if (!count) return null_argument(&s.error, "filigree_session_clip_count", "count");
    *count = static_cast<std::size_t>(s.mesh.skeleton.clips_size());
    return FILIGREE_OK;
  });
}

int filigree_session_clip_name(const filigree_session* session, size_t clip, char* buffer, size_t capacity,
                               size_t* required) {
  constexpr const char* kFunction = "filigree_session_clip_name";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    const std::size_t count = static_cast<std::size_t>(s.mesh.skeleton.clips_size());
    if (clip >= count) return out_of_range(s, kFunction, "clip", clip, count);
    return copy_string(&s.error, kFunction, s.mesh.skeleton.clips(static_cast<int>(clip)).name(), buffer, capacity,
                       required);
  });
}

int filigree_session_clip_duration(const filigree_session* session, size_t clip, double* seconds) {
  constexpr const char* kFunction = "filigree_session_clip_duration";
  return with_handle(session, kFunction, [&](const filigree_session& s) -> int {
    if (!seconds) return null_argument(&s.error, kFunction, "seconds");
    const std::size_t count = static_cast<std::size_t>(s.mesh.skeleton.clips_size());
    if (clip >= count) return out_of_range(s, kFunction, "clip", clip, count);
    *seconds = s.mesh.skeleton.clips(static_cast<int>(clip)).duration_seconds();
    return FILIGREE_OK;
  });
}

int filigree_close_session(filigree_session* session, const char* token) {
  return with_handle(session, "filigree_close_session", [&](filigree_session& s) -> int {
    s.connection->client.close(s.mesh.session_id, token ? token : s.token);
    return FILIGREE_OK;
  });
}

const char* filigree_session_last_error(const filigree_session* session) {
  return is_handle(session, filigree_session::kKind) ? session->error.get() : invalid_handle_message();
}

int filigree_session_free(filigree_session* session) {
  if (!session) return FILIGREE_OK;
  if (!unregister_handle(session, filigree_session::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_session_free: not a live filigree_session (freed, or another kind of handle)");
  delete session;
  return FILIGREE_OK;
}

}  // extern "C"
