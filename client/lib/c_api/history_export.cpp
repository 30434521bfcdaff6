// The history's export: the state after each entry of a range, read one at
// a time on the caller's thread.

#include "c_api/collaboration.h"

namespace filigree::c_api {
namespace {

// Records why the stream ended (the first time: CANCELLED after close() is
// a normal end, as for watchers) and returns it.
FrameStream::End ended(filigree_history_export& e, const grpc::Status& status) {
  std::lock_guard lock(e.state_mutex);
  if (!e.ended) {
    if (!status.ok() && !(e.closed && status.error_code() == grpc::StatusCode::CANCELLED))
      e.end = FrameStream::End{status_of(status.error_code()),
                               std::string(status_code_name(status.error_code())) + ": " + status.error_message()};
    e.ended = true;
  }
  return e.end;
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_export_history(filigree_session* session, const char* token, uint64_t from_entry, uint64_t to_entry,
                            filigree_history_export** out) {
  constexpr const char* kFunction = "filigree_export_history";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    if (!out) return null_argument(&s.error, kFunction, "out");
    *out = nullptr;
    auto handle = std::make_unique<filigree_history_export>();
    handle->connection = s.connection;
    handle->float_count = s.mesh.rest_positions.size();
    handle->stream = s.connection->client.export_history(s.mesh.session_id, token ? token : s.token,
                                                         s.mesh.rest_positions, from_entry, to_entry);
    return hand_out(std::move(handle), out);
  });
}

int filigree_history_export_next(filigree_history_export* history_export, float* positions, size_t capacity,
                                 size_t* required, filigree_history_state* state) {
  constexpr const char* kFunction = "filigree_history_export_next";
  return with_handle(history_export, kFunction, [&](filigree_history_export& e) -> int {
    if (required) *required = e.float_count;
    if (!positions && capacity > 0) return null_argument(&e.error, kFunction, "positions");
    if (capacity < e.float_count)
      return fail(&e.error, FILIGREE_ERROR_BUFFER_TOO_SMALL,
                  std::string(kFunction) + ": the buffer holds " + std::to_string(capacity) + " floats, a state needs " +
                      std::to_string(e.float_count) + " (3 per vertex)");
    std::lock_guard read_lock(e.read_mutex);
    {
      std::lock_guard lock(e.state_mutex);
      if (e.ended) return FrameStream::report_end(e.error, kFunction, e.end);
    }
    std::optional<filigree::HistoryState> next;
    try {
      next = e.stream->read();
    } catch (const filigree::ClientError& error) {  // a state that does not decode: the stream is cancelled
      e.stream->finish();
      std::lock_guard lock(e.state_mutex);
      e.end = FrameStream::End{status_of(error.code()), error.what()};
      e.ended = true;
      return fail(&e.error, e.end.status, std::string(kFunction) + ": " + error.what());
    }
    if (!next) return FrameStream::report_end(e.error, kFunction, ended(e, e.stream->finish()));
    std::copy(next->positions.begin(), next->positions.end(), positions);
    if (state) *state = filigree_history_state{next->entry, next->version, next->time, next->max_error};
    next->positions = {};  // kept: the author and the base pose
    std::lock_guard lock(e.state_mutex);
    e.latest = std::move(next);
    return FILIGREE_OK;
  });
}

int filigree_history_export_author(const filigree_history_export* history_export, char* buffer, size_t capacity,
                                   size_t* required) {
  constexpr const char* kFunction = "filigree_history_export_author";
  return with_handle(history_export, kFunction, [&](const filigree_history_export& e) -> int {
    std::lock_guard lock(e.state_mutex);
    return copy_string(&e.error, kFunction, e.latest ? e.latest->author : std::string(), buffer, capacity, required);
  });
}

int filigree_history_export_base_pose(const filigree_history_export* history_export, float* buffer, size_t capacity,
                                      size_t* required) {
  constexpr const char* kFunction = "filigree_history_export_base_pose";
  return with_handle(history_export, kFunction, [&](const filigree_history_export& e) -> int {
    std::lock_guard lock(e.state_mutex);
    static const std::vector<float> kNone;
    const std::vector<float>& pose = e.latest ? e.latest->base_pose : kNone;
    return copy_out(&e.error, kFunction, pose.data(), pose.size(), sizeof(float), buffer, capacity, required);
  });
}

int filigree_history_export_close(filigree_history_export* history_export) {
  constexpr const char* kFunction = "filigree_history_export_close";
  return with_handle(history_export, kFunction, [&](filigree_history_export& e) -> int {
    {
      std::lock_guard lock(e.state_mutex);
      e.closed = true;
    }
    e.stream->cancel();  // wakes a next() blocked in another thread
    std::lock_guard read_lock(e.read_mutex);
    const FrameStream::End end = ended(e, e.stream->finish());
    if (end.status == FILIGREE_OK) return FILIGREE_OK;
    return fail(&e.error, end.status, std::string(kFunction) + ": the stream ended: " + end.message);
  });
}

const char* filigree_history_export_last_error(const filigree_history_export* history_export) {
  return is_handle(history_export, filigree_history_export::kKind) ? history_export->error.get()
                                                                   : invalid_handle_message();
}

int filigree_history_export_free(filigree_history_export* history_export) {
  if (!history_export) return FILIGREE_OK;
  if (!unregister_handle(history_export, filigree_history_export::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                "filigree_history_export_free: not a live filigree_history_export (freed, or another kind of handle)");
  delete history_export;  // the stream is cancelled and drained unless finished
  return FILIGREE_OK;
}

}  // extern "C"
