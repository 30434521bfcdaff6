// Editing a session besides poses: handles and the cut threshold.

#include <array>
#include <limits>
#include <vector>

#include "c_api/internal.h"

namespace filigree::c_api {
namespace {

// filigree_set_handles and filigree_set_handles_in_gesture.
int set_handles(filigree_session* session, const char* function, const char* token, const char* client_name,
                std::uint64_t gesture_id, const uint32_t* vertices, size_t vertex_count, const float* targets,
                size_t float_count, uint32_t* handles_in_session) {
  return with_handle(session, function, [&](filigree_session& s) -> int {
    if (!vertices && vertex_count > 0) return null_argument(&s.error, function, "vertices");
    if (!targets && float_count > 0) return null_argument(&s.error, function, "targets");
    if (float_count != 3 * vertex_count)
      return fail(&s.error, FILIGREE_INVALID_ARGUMENT,
                  std::string(function) + ": " + std::to_string(float_count) + " target floats for " +
                      std::to_string(vertex_count) + " vertices; expected " + std::to_string(3 * vertex_count));
    const std::size_t n = s.mesh.rest_positions.size() / 3;
    for (std::size_t i = 0; i < vertex_count; ++i)
      if (vertices[i] >= n)
        return fail(&s.error, FILIGREE_INVALID_ARGUMENT,
                    std::string(function) + ": vertex " + std::to_string(vertices[i]) + " at position " +
                        std::to_string(i) + " is out of range: the mesh has " + std::to_string(n) + " vertices");
    std::vector<std::array<float, 3>> points(vertex_count);
    for (std::size_t i = 0; i < vertex_count; ++i) points[i] = {targets[3 * i], targets[3 * i + 1], targets[3 * i + 2]};
    const std::uint32_t count = s.connection->client.set_handles(
        s.mesh.session_id, token ? token : s.token, client_name ? client_name : "filigree-c", {vertices, vertex_count},
        points, gesture_id);
    if (handles_in_session) *handles_in_session = count;
    return FILIGREE_OK;
  });
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_set_handles(filigree_session* session, const char* token, const char* client_name,
                         const uint32_t* vertices, size_t vertex_count, const float* targets, size_t float_count,
                         uint32_t* handles_in_session) {
  return set_handles(session, "filigree_set_handles", token, client_name, 0, vertices, vertex_count, targets,
                     float_count, handles_in_session);
}

int filigree_set_handles_in_gesture(filigree_session* session, const char* token, const char* client_name,
                                    uint64_t gesture_id, const uint32_t* vertices, size_t vertex_count,
                                    const float* targets, size_t float_count, uint32_t* handles_in_session) {
  return set_handles(session, "filigree_set_handles_in_gesture", token, client_name, gesture_id, vertices,
                     vertex_count, targets, float_count, handles_in_session);
}

int filigree_set_threshold(filigree_session* session, const char* token, double threshold, int whole_mesh) {
  constexpr const char* kFunction = "filigree_set_threshold";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!(threshold >= 0.0) || threshold == std::numeric_limits<double>::infinity())
      return fail(&s.error, FILIGREE_INVALID_ARGUMENT,
                  std::string(kFunction) + ": the threshold must be finite and ≥ 0 (whole_mesh asks for T = ∞)");
    s.connection->client.set_threshold(s.mesh.session_id, token ? token : s.token, threshold, whole_mesh != 0);
    return FILIGREE_OK;
  });
}

}  // extern "C"
