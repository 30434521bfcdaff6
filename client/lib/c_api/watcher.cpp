// Watchers: a Watch or PlayClip stream whose frames a FrameStream decodes in
// the background, for a callback or for polls.

#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>
#include <vector>

#include "c_api/internal.h"

namespace filigree::c_api {
namespace {

// How long filigree_watcher_set_detail waits for the stream's level (its
// first message) when called right after the open.
constexpr std::chrono::seconds kLevelWait{30};

// Wraps a Watcher made by `open` (Client::watch or Client::play_clip) in a
// handle; `at_level`: it was opened with a vertex budget.
template <class Open>
int open_watcher(filigree_session& s, const char* function, filigree_frame_callback callback, void* user,
                 filigree_watcher** out, bool at_level, Open&& open) {
  if (!out) return null_argument(&s.error, function, "out");
  *out = nullptr;
  auto handle = std::make_unique<filigree_watcher>();
  handle->connection = s.connection;
  handle->at_level = at_level;
  filigree::Reconnect reconnect;
  reconnect.on_reconnect = [w = handle.get()](const grpc::Status&, int) { ++w->reconnects; };
  handle->watcher = open(std::move(reconnect));
  filigree::Watcher* w = handle->watcher.get();
  FrameStream::Hooks hooks{[w] { return w->read(); }, [w] { return w->finish(); }, [w] { w->cancel(); }};
  handle->stream = std::make_unique<FrameStream>(std::move(hooks), s.mesh.rest_positions,
                                                 s.connection->decode_threads.load(), callback, user, at_level);
  return hand_out(std::move(handle), out);
}

// A level's array (ids or faces) of the latest polled frame: empty at full detail.
template <class Get>
int copy_level_array(const filigree_watcher* watcher, const char* function, Get&& get, uint32_t* buffer,
                     size_t capacity, size_t* required) {
  return with_handle(watcher, function, [&](const filigree_watcher& w) -> int {
    const std::shared_ptr<const filigree::DecodedLevel> level = w.stream->level();
    static const std::vector<std::uint32_t> kNone;
    const std::vector<std::uint32_t>& values = level ? get(*level) : kNone;
    return copy_out(&w.error, function, values.data(), values.size(), sizeof(std::uint32_t), buffer, capacity,
                    required);
  });
}

// What is wrong with a playback's numbers (the server's rules for
// PlayClipRequest), checked here so that a bad one fails the call itself
// rather than the stream later; nullopt when nothing is.
std::optional<std::string> playback_error(const filigree::ClipPlayback& p) {
  const auto text = [](double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%g", v);
    return std::string(buffer);
  };
  if (!std::isfinite(p.speed) || p.speed < 0.0)
    return "speed must be finite and >= 0 (0 means 1), not " + text(p.speed);
  if (!std::isfinite(p.start_seconds)) return "start_seconds must be finite, not " + text(p.start_seconds);
  if (!std::isfinite(p.max_rate) || p.max_rate < 0.0)
    return "max_rate must be finite and >= 0 (0: as fast as frames compute), not " + text(p.max_rate);
  return std::nullopt;
}

// filigree_play_clip and filigree_play_clip_with, after the handle check.
int play_clip(filigree_session& s, const char* function, const char* token, const char* clip,
              const filigree::ClipPlayback& playback, filigree_frame_callback callback, void* user,
              filigree_watcher** out) {
  if (!clip) return null_argument(&s.error, function, "clip");
  if (!out) return null_argument(&s.error, function, "out");
  *out = nullptr;
  if (const auto why = playback_error(playback))
    return fail(&s.error, FILIGREE_INVALID_ARGUMENT, std::string(function) + ": " + *why);
  return open_watcher(s, function, callback, user, out, false, [&](filigree::Reconnect) {
    return s.connection->client.play_clip(s.mesh.session_id, token ? token : s.token, clip, playback, "filigree-c");
  });
}

int wrong_thread(filigree_watcher& w, const char* function) {
  return fail(&w.error, FILIGREE_ERROR_WRONG_THREAD,
              std::string(function) + ": called from the watcher's own callback (it would wait for itself)");
}

int end_status(filigree_watcher& w, const char* function) {
  const FrameStream::End end = w.stream->end();
  if (end.status == FILIGREE_OK) return FILIGREE_OK;
  return fail(&w.error, end.status, std::string(function) + ": the stream ended: " + end.message);
}

}  // namespace
}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

int filigree_watcher_open(filigree_session* session, const char* token, uint64_t after_version,
                          filigree_frame_callback callback, void* user, filigree_watcher** out) {
  constexpr const char* kFunction = "filigree_watcher_open";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    return open_watcher(s, kFunction, callback, user, out, false, [&](filigree::Reconnect reconnect) {
      return s.connection->client.watch(s.mesh.session_id, token ? token : s.token, after_version,
                                        std::move(reconnect));
    });
  });
}

int filigree_watcher_open_with(filigree_session* session, const char* token, const filigree_watch_options* options,
                               filigree_frame_callback callback, void* user, filigree_watcher** out) {
  constexpr const char* kFunction = "filigree_watcher_open_with";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    filigree::WatchOptions watch;  // NULL options: these defaults
    if (options) {
      watch.after_version = options->after_version;
      watch.max_vertices = options->max_vertices;
    }
    return open_watcher(s, kFunction, callback, user, out, watch.max_vertices > 0, [&](filigree::Reconnect reconnect) {
      return s.connection->client.watch(s.mesh.session_id, token ? token : s.token, watch, std::move(reconnect));
    });
  });
}

int filigree_play_clip(filigree_session* session, const char* token, const char* clip, double speed, int loop,
                       filigree_frame_callback callback, void* user, filigree_watcher** out) {
  constexpr const char* kFunction = "filigree_play_clip";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    filigree::ClipPlayback playback;
    playback.speed = speed;
    playback.loop = loop != 0;
    return play_clip(s, kFunction, token, clip, playback, callback, user, out);
  });
}

int filigree_play_clip_with(filigree_session* session, const char* token, const char* clip,
                            const filigree_clip_playback* options, filigree_frame_callback callback, void* user,
                            filigree_watcher** out) {
  constexpr const char* kFunction = "filigree_play_clip_with";
  return with_handle(session, kFunction, [&](filigree_session& s) -> int {
    filigree::ClipPlayback playback;  // NULL options: these defaults
    if (options) {
      playback.speed = options->speed;
      playback.loop = options->loop != 0;
      playback.start_seconds = options->start_seconds;
      playback.max_rate = options->max_rate;
    }
    return play_clip(s, kFunction, token, clip, playback, callback, user, out);
  });
}

int filigree_watcher_poll(filigree_watcher* watcher, float* positions, size_t capacity, uint64_t* version,
                          uint64_t* pose_id, int* updated) {
  constexpr const char* kFunction = "filigree_watcher_poll";
  return with_handle(watcher, kFunction, [&](filigree_watcher& w) -> int {
    return w.stream->poll(w.error, kFunction, positions, capacity, version, pose_id, updated);
  });
}

int filigree_watcher_frame_info(const filigree_watcher* watcher, filigree_frame_info* info) {
  constexpr const char* kFunction = "filigree_watcher_frame_info";
  return with_handle(watcher, kFunction, [&](const filigree_watcher& w) -> int {
    if (!info) return null_argument(&w.error, kFunction, "info");
    *info = w.stream->info();
    return FILIGREE_OK;
  });
}

int filigree_watcher_clip_seconds(const filigree_watcher* watcher, double* seconds) {
  constexpr const char* kFunction = "filigree_watcher_clip_seconds";
  return with_handle(watcher, kFunction, [&](const filigree_watcher& w) -> int {
    if (!seconds) return null_argument(&w.error, kFunction, "seconds");
    *seconds = w.stream->clip_seconds();
    return FILIGREE_OK;
  });
}

int filigree_watcher_wait(filigree_watcher* watcher, int64_t timeout_ms) {
  constexpr const char* kFunction = "filigree_watcher_wait";
  return with_handle(watcher, kFunction, [&](filigree_watcher& w) -> int {
    if (timeout_ms != 0 && w.stream->on_own_thread()) return wrong_thread(w, kFunction);
    if (!w.stream->wait(timeout_of(timeout_ms)))
      return fail(&w.error, FILIGREE_DEADLINE_EXCEEDED, std::string(kFunction) + ": the stream is still going");
    return end_status(w, kFunction);
  });
}

int filigree_watcher_wait_frame(filigree_watcher* watcher, int64_t timeout_ms) {
  constexpr const char* kFunction = "filigree_watcher_wait_frame";
  return with_handle(watcher, kFunction, [&](filigree_watcher& w) -> int {
    return w.stream->wait_frame(w.error, kFunction, timeout_of(timeout_ms));
  });
}

int filigree_watcher_level_vertex_count(const filigree_watcher* watcher, size_t* count) {
  constexpr const char* kFunction = "filigree_watcher_level_vertex_count";
  return with_handle(watcher, kFunction, [&](const filigree_watcher& w) -> int {
    if (!count) return null_argument(&w.error, kFunction, "count");
    *count = w.stream->level_vertex_count();
    return FILIGREE_OK;
  });
}

int filigree_watcher_level_original_ids(const filigree_watcher* watcher, uint32_t* buffer, size_t capacity,
                                        size_t* required) {
  return copy_level_array(
      watcher, "filigree_watcher_level_original_ids",
      [](const filigree::DecodedLevel& l) -> const std::vector<std::uint32_t>& { return l.original_ids; }, buffer,
      capacity, required);
}

int filigree_watcher_level_faces(const filigree_watcher* watcher, uint32_t* buffer, size_t capacity,
                                 size_t* required) {
  return copy_level_array(
      watcher, "filigree_watcher_level_faces",
      [](const filigree::DecodedLevel& l) -> const std::vector<std::uint32_t>& { return l.faces; }, buffer, capacity,
      required);
}

int filigree_watcher_set_detail(filigree_watcher* watcher, uint32_t max_vertices, uint32_t* vertex_count) {
  constexpr const char* kFunction = "filigree_watcher_set_detail";
  return with_handle(watcher, kFunction, [&](filigree_watcher& w) -> int {
    if (max_vertices == 0)
      return fail(&w.error, FILIGREE_INVALID_ARGUMENT, std::string(kFunction) + ": a budget is at least 1 vertex");
    if (w.at_level) {
      // Right after the open the level (the stream's first message, which
      // names the stream) may not have come yet.
      if (const int status = w.stream->wait_level(w.error, kFunction, kLevelWait); status != FILIGREE_OK) return status;
    }
    const std::uint32_t count = w.watcher->set_detail(max_vertices);
    if (vertex_count) *vertex_count = count;
    return FILIGREE_OK;
  });
}

int filigree_watcher_reconnects(const filigree_watcher* watcher, uint64_t* count) {
  constexpr const char* kFunction = "filigree_watcher_reconnects";
  return with_handle(watcher, kFunction, [&](const filigree_watcher& w) -> int {
    if (!count) return null_argument(&w.error, kFunction, "count");
    *count = w.reconnects.load();
    return FILIGREE_OK;
  });
}

int filigree_watcher_changes(const filigree_watcher* watcher, char* buffer, size_t capacity, size_t* required) {
  constexpr const char* kFunction = "filigree_watcher_changes";
  return with_handle(watcher, kFunction, [&](const filigree_watcher& w) -> int {
    return copy_string(&w.error, kFunction, w.stream->changes(), buffer, capacity, required);
  });
}

int filigree_watcher_close(filigree_watcher* watcher) {
  constexpr const char* kFunction = "filigree_watcher_close";
  return with_handle(watcher, kFunction, [&](filigree_watcher& w) -> int {
    if (w.stream->on_own_thread()) return wrong_thread(w, kFunction);
    w.stream->stop();
    w.stream->join();
    return end_status(w, kFunction);
  });
}

const char* filigree_watcher_last_error(const filigree_watcher* watcher) {
  return is_handle(watcher, filigree_watcher::kKind) ? watcher->error.get() : invalid_handle_message();
}

int filigree_watcher_free(filigree_watcher* watcher) {
  if (!watcher) return FILIGREE_OK;
  constexpr const char* kInvalid =
      "filigree_watcher_free: not a live filigree_watcher (freed, or another kind of handle)";
  if (!is_handle(watcher, filigree_watcher::kKind)) return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE, kInvalid);
  if (watcher->stream->on_own_thread()) return wrong_thread(*watcher, "filigree_watcher_free");
  if (!unregister_handle(watcher, filigree_watcher::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE, kInvalid);
  // The stream goes first (declared last): cancelled, its thread joined.
  delete watcher;
  return FILIGREE_OK;
}

}  // extern "C"
