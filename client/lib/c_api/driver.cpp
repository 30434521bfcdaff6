// Drivers: a Drive stream whose frames a FrameStream decodes in the background.

#include <chrono>
#include <span>

#include "c_api/internal.h"

namespace filigree::c_api {
namespace {

// Runs `write` (a Driver::send*) unless the stream has ended. A write that
// fails means the call is over: the reader thread then sees the end and
// finishes the call, and the status says why.
template <class Write>
int send(filigree_driver& d, const char* function, Write&& write) {
  if (d.viewer_only)
    return fail(&d.error, FILIGREE_PERMISSION_DENIED,
                std::string(function) + ": the session was joined with a viewer token, which cannot drive (join with "
                                        "its editor token, or give one to filigree_driver_open)");
  {
    std::lock_guard lock(d.send_mutex);
    if (!d.stream->wait(std::chrono::milliseconds(0)) && write()) return FILIGREE_OK;
  }
  d.stream->wait(std::nullopt);
  return FrameStream::report_end(d.error, function, d.stream->end());
}

int invalid(filigree_driver& d, const char* function, const std::string& message) {
  return fail(&d.error, FILIGREE_INVALID_ARGUMENT, std::string(function) + ": " + message);
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_driver_open(filigree_session* session, const char* token, const char* client_name,
                         filigree_driver** out) {
  constexpr const char* kFunction = "filigree_driver_open";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!out) return null_argument(&s.error, kFunction, "out");
    *out = nullptr;
    auto handle = std::make_unique<filigree_driver>();
    handle->connection = s.connection;
    handle->base_vertex_count = s.mesh.base_vertex_count();
    // Driving with the token the session was joined with, a viewer's: every
    // send says so at once, rather than the stream ending at the first frame.
    handle->viewer_only = !token && s.mesh.role == filigree::v1::ROLE_VIEWER;
    handle->joint_count = static_cast<std::size_t>(s.mesh.skeleton.joints_size());
    filigree::Reconnect reconnect;
    reconnect.on_reconnect = [d = handle.get()](const grpc::Status&, int) { ++d->reconnects; };
    handle->driver = s.connection->client.drive(s.mesh.session_id, token ? token : s.token,
                                                client_name ? client_name : "filigree-c", std::move(reconnect));
    filigree_driver* d = handle.get();
    FrameStream::Hooks hooks{
        [d] { return d->driver->read(); },
        [d] {
          // finish() half-closes the call: not while a send is writing.
          std::lock_guard lock(d->send_mutex);
          return d->driver->finish();
        },
        [d] { d->driver->cancel(); }};
    handle->stream = std::make_unique<FrameStream>(std::move(hooks), s.mesh.rest_positions,
                                                   s.connection->decode_threads.load(), nullptr, nullptr);
    return hand_out(std::move(handle), out);
  });
}

int filigree_driver_send_positions(filigree_driver* driver, uint64_t pose_id, const float* positions,
                                   size_t float_count) {
  constexpr const char* kFunction = "filigree_driver_send_positions";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    if (!positions) return null_argument(&d.error, kFunction, "positions");
    // Checked here rather than by the server, which would end the stream.
    if (float_count != 3 * d.base_vertex_count)
      return invalid(d, kFunction,
                     std::to_string(float_count) + " floats for " + std::to_string(d.base_vertex_count) +
                         " base vertices (3 per vertex expected)");
    return send(d, kFunction, [&] { return d.driver->send(pose_id, std::span<const float>(positions, float_count)); });
  });
}

int filigree_driver_send_partial(filigree_driver* driver, uint64_t pose_id, const uint32_t* indices,
                                 size_t index_count, const float* positions, size_t float_count) {
  constexpr const char* kFunction = "filigree_driver_send_partial";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    if (!indices) return null_argument(&d.error, kFunction, "indices");
    if (!positions) return null_argument(&d.error, kFunction, "positions");
    // No indices would mean "all vertices" on the wire.
    if (index_count == 0) return invalid(d, kFunction, "no indices (a full pose is filigree_driver_send_positions)");
    if (float_count != 3 * index_count)
      return invalid(d, kFunction,
                     std::to_string(float_count) + " floats for " + std::to_string(index_count) +
                         " indices (3 per index expected)");
    for (std::size_t k = 0; k < index_count; ++k)
      if (indices[k] >= d.base_vertex_count)
        return invalid(d, kFunction,
                       "indices[" + std::to_string(k) + "] = " + std::to_string(indices[k]) + " is not a base vertex (" +
                           std::to_string(d.base_vertex_count) + ")");
    return send(d, kFunction, [&] {
      return d.driver->send_partial(pose_id, std::span<const std::uint32_t>(indices, index_count),
                                    std::span<const float>(positions, float_count));
    });
  });
}

int filigree_driver_send_joints(filigree_driver* driver, uint64_t pose_id, int space, const uint32_t* joints,
                                size_t joint_count, const float* values, size_t value_count) {
  constexpr const char* kFunction = "filigree_driver_send_joints";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    if (space != FILIGREE_JOINTS_LOCAL_TRS && space != FILIGREE_JOINTS_MODEL_MATRIX)
      return invalid(d, kFunction, "space " + std::to_string(space) + " is neither FILIGREE_JOINTS_LOCAL_TRS nor "
                                                                     "FILIGREE_JOINTS_MODEL_MATRIX");
    if (!values) return null_argument(&d.error, kFunction, "values");
    if (d.joint_count == 0)
      return fail(&d.error, FILIGREE_FAILED_PRECONDITION, std::string(kFunction) + ": the session has no skeleton");
    const std::size_t per_joint = space == FILIGREE_JOINTS_MODEL_MATRIX ? 16 : 10;
    const std::size_t named = joints ? joint_count : d.joint_count;
    // An empty list would mean "all joints" on the wire.
    if (joints && joint_count == 0) return invalid(d, kFunction, "no joints (NULL `joints` poses all of them)");
    if (value_count != per_joint * named)
      return invalid(d, kFunction,
                     std::to_string(value_count) + " values for " + std::to_string(named) + " joints (" +
                         std::to_string(per_joint) + " per joint expected)");
    for (std::size_t k = 0; joints && k < joint_count; ++k)
      if (joints[k] >= d.joint_count)
        return invalid(d, kFunction,
                       "joints[" + std::to_string(k) + "] = " + std::to_string(joints[k]) + " is not a joint (" +
                           std::to_string(d.joint_count) + ")");
    const auto wire_space = space == FILIGREE_JOINTS_MODEL_MATRIX ? filigree::v1::JointPose::SPACE_MODEL_MATRIX
                                                                  : filigree::v1::JointPose::SPACE_LOCAL_TRS;
    return send(d, kFunction, [&] {
      return d.driver->send_joints(pose_id, wire_space,
                                   joints ? std::span<const std::uint32_t>(joints, joint_count)
                                          : std::span<const std::uint32_t>(),
                                   std::span<const float>(values, value_count));
    });
  });
}

int filigree_driver_set_gesture(filigree_driver* driver, uint64_t gesture_id) {
  return with_handle(driver, "filigree_driver_set_gesture", [&](filigree_driver& d) -> int {
    d.driver->set_gesture(gesture_id);
    return FILIGREE_OK;
  });
}

int filigree_driver_poll(filigree_driver* driver, float* positions, size_t capacity, uint64_t* version,
                         uint64_t* pose_id, int* updated) {
  constexpr const char* kFunction = "filigree_driver_poll";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    return d.stream->poll(d.error, kFunction, positions, capacity, version, pose_id, updated);
  });
}

int filigree_driver_frame_info(const filigree_driver* driver, filigree_frame_info* info) {
  constexpr const char* kFunction = "filigree_driver_frame_info";
  return with_handle(driver, kFunction, [&](const filigree_driver& d) -> int {
    if (!info) return null_argument(&d.error, kFunction, "info");
    *info = d.stream->info();
    return FILIGREE_OK;
  });
}

int filigree_driver_wait_frame(filigree_driver* driver, int64_t timeout_ms) {
  constexpr const char* kFunction = "filigree_driver_wait_frame";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    return d.stream->wait_frame(d.error, kFunction, timeout_of(timeout_ms));
  });
}

int filigree_driver_wait_for_pose(filigree_driver* driver, uint64_t pose_id, int64_t timeout_ms) {
  constexpr const char* kFunction = "filigree_driver_wait_for_pose";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    return d.stream->wait_for_pose(d.error, kFunction, pose_id, timeout_of(timeout_ms));
  });
}

int filigree_driver_reconnects(const filigree_driver* driver, uint64_t* count) {
  constexpr const char* kFunction = "filigree_driver_reconnects";
  return with_handle(driver, kFunction, [&](const filigree_driver& d) -> int {
    if (!count) return null_argument(&d.error, kFunction, "count");
    *count = d.reconnects.load();
    return FILIGREE_OK;
  });
}

int filigree_driver_changes(const filigree_driver* driver, char* buffer, size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_driver_changes";
  return with_handle(driver, kFunction, [&](const filigree_driver& d) -> int {
    return copy_string(&d.error, kFunction, d.stream->changes(), buffer, capacity, required);
  });
}

int filigree_driver_close(filigree_driver* driver) {
  constexpr const char* kFunction = "filigree_driver_close";
  return with_handle(driver, kFunction, [&](filigree_driver& d) -> int {
    {
      // The server ends the stream once it has read the half-close.
      std::lock_guard lock(d.send_mutex);
      d.driver->writes_done();
    }
    d.stream->join();
    const FrameStream::End end = d.stream->end();
    if (end.status == FILIGREE_OK) return FILIGREE_OK;
    return fail(&d.error, end.status, std::string(kFunction) + ": the stream ended: " + end.message);
  });
}

const char* filigree_driver_last_error(const filigree_driver* driver) {
  return is_handle(driver, filigree_driver::kKind) ? driver->error.get() : invalid_handle_message();
}

int filigree_driver_free(filigree_driver* driver) {
  if (!driver) return FILIGREE_OK;
  if (!unregister_handle(driver, filigree_driver::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_driver_free: not a live filigree_driver (freed, or another kind of handle)");
  // The stream goes first (declared last): cancelled unless closed, its thread joined.
  delete driver;
  return FILIGREE_OK;
}

}  // extern "C"
