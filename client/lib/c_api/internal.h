#pragma once
// Internals of the C API (include/filigree/filigree.h): the handle structs,
// the registry that tells live handles from anything else, and the error
// plumbing every exported function goes through so that no exception
// crosses into C.

#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>

#include "c_api/frame_stream.h"
#include "filigree/client.h"
#include "filigree/filigree.h"

namespace filigree::c_api {

enum class Kind : std::uint8_t { kClient, kSession, kDriver, kWatcher, kHistory, kPresence, kHistoryExport };

// Live handles by address. A lookup on every call costs a mutex and a hash
// probe, nothing next to a frame, and it turns NULL, a freed handle or one
// of the wrong kind (easy to pass through an IntPtr) into a status instead
// of a crash.
void register_handle(const void* handle, Kind kind);
// False if `handle` was not a live handle of `kind` (then nothing changes).
bool unregister_handle(const void* handle, Kind kind);
bool is_handle(const void* handle, Kind kind);

// One handle's last error message. get()'s pointer stays valid until the
// next set() (documented in filigree.h).
class ErrorSlot {
 public:
  void set(std::string_view message) noexcept;
  const char* get() const noexcept;

 private:
  mutable std::mutex mutex_;
  std::string message_;
};

// Records a failure in the calling thread's message and, unless null, in
// `slot`; returns `status` so that callers can `return fail(…)`.
int fail(ErrorSlot* slot, int status, std::string_view message) noexcept;

// The C status of a gRPC status (the numbers are the same by design).
int status_of(grpc::StatusCode code);

// Runs `body` (which returns a status) and turns any exception into a
// status and a message prefixed with `function`.
template <class Body>
int guarded(ErrorSlot* slot, const char* function, Body&& body) noexcept {
  try {
    return body();
  } catch (const ClientError& e) {
    return fail(slot, status_of(e.code()), std::string(function) + ": " + e.what());
  } catch (const std::bad_alloc&) {
    return fail(slot, FILIGREE_ERROR_OUT_OF_MEMORY, std::string(function) + ": out of memory");
  } catch (const std::invalid_argument& e) {
    return fail(slot, FILIGREE_INVALID_ARGUMENT, std::string(function) + ": " + e.what());
  } catch (const std::exception& e) {
    return fail(slot, FILIGREE_UNKNOWN, std::string(function) + ": " + e.what());
  } catch (...) {
    return fail(slot, FILIGREE_UNKNOWN, std::string(function) + ": unknown exception");
  }
}

// A null pointer argument: FILIGREE_ERROR_NULL_ARGUMENT naming it.
int null_argument(ErrorSlot* slot, const char* function, const char* argument) noexcept;

// Copies `count` elements into a caller's buffer under the rules of
// filigree.h (size query, too small, NULL buffer).
int copy_out(ErrorSlot* slot, const char* function, const void* data, std::size_t count, std::size_t element_size,
             void* buffer, std::size_t capacity, std::size_t* required) noexcept;
// A string with its NUL.
int copy_string(ErrorSlot* slot, const char* function, const std::string& s, char* buffer, std::size_t capacity,
                std::size_t* required) noexcept;

// What every handle made from one filigree_connect shares: handles may be
// freed in any order, and the last one closes the channel.
struct Connection {
  // Client's own insecure channel (its message size and retry settings).
  explicit Connection(const std::string& target) : client(target) {}
  Connection(const std::string& target, const std::shared_ptr<grpc::ChannelCredentials>& credentials)
      : client(target, credentials) {}
  Client client;
  std::atomic<unsigned> decode_threads{0};
};

}  // namespace filigree::c_api

// The opaque types of filigree.h. Each names its Kind for the registry.
struct filigree_client {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kClient;
  static constexpr const char* kName = "filigree_client";
  std::shared_ptr<filigree::c_api::Connection> connection;
  mutable filigree::c_api::ErrorSlot error;  // mutable: accessors on const handles record failures too
};

struct filigree_session {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kSession;
  static constexpr const char* kName = "filigree_session";
  std::shared_ptr<filigree::c_api::Connection> connection;
  std::string editor_token, viewer_token;  // empty for a joined session
  std::string token;                       // what it was made (editor) or joined with
  filigree::SessionMesh mesh;
  // The latest undo, redo or restore made through this handle
  // (filigree_session_edit_message, filigree_session_edit_conflicts).
  mutable std::mutex edit_mutex;
  std::string edit_message, edit_conflicts;
  mutable filigree::c_api::ErrorSlot error;  // mutable: accessors on const handles record failures too
};

struct filigree_driver {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kDriver;
  static constexpr const char* kName = "filigree_driver";
  std::shared_ptr<filigree::c_api::Connection> connection;
  std::size_t base_vertex_count = 0, joint_count = 0;  // for checking poses here
  bool viewer_only = false;  // opened with the viewer token a session was joined with: sends are refused here
  // Serialises the writes of several sending threads and the reader
  // thread's finish() (gRPC allows one writer at a time).
  std::mutex send_mutex;
  std::atomic<std::uint64_t> reconnects{0};  // attempts to reopen the stream (Reconnect)
  std::unique_ptr<filigree::Driver> driver;
  std::unique_ptr<filigree::c_api::FrameStream> stream;  // declared after driver: stopped first
  mutable filigree::c_api::ErrorSlot error;  // mutable: accessors on const handles record failures too
};

struct filigree_watcher {
  static constexpr filigree::c_api::Kind kKind = filigree::c_api::Kind::kWatcher;
  static constexpr const char* kName = "filigree_watcher";
  std::shared_ptr<filigree::c_api::Connection> connection;
  std::atomic<std::uint64_t> reconnects{0};  // attempts to reopen the stream (Reconnect)
  bool at_level = false;  // opened with a vertex budget: its level can change
  std::unique_ptr<filigree::Watcher> watcher;
  std::unique_ptr<filigree::c_api::FrameStream> stream;  // declared after watcher: stopped first
  mutable filigree::c_api::ErrorSlot error;  // mutable: accessors on const handles record failures too
};

namespace filigree::c_api {

// Checks that `handle` is a live H, then runs `body(*handle)` guarded, with
// failures recorded in the handle too.
template <class H, class Body>
int with_handle(H* handle, const char* function, Body&& body) noexcept {
  if (!is_handle(handle, H::kKind))
    return fail(nullptr, FILIGREE_ERROR_INVALID_HANDLE,
                std::string(function) + ": not a live " + H::kName + " (NULL, freed, or another kind of handle)");
  return guarded(&handle->error, function, [&] { return body(*handle); });
}

// Registers a new handle and hands it out through `out`.
template <class H>
int hand_out(std::unique_ptr<H> handle, H** out) {
  register_handle(handle.get(), H::kKind);
  *out = handle.release();
  return FILIGREE_OK;
}

// A C timeout in milliseconds: negative means none (nullopt).
inline std::optional<std::chrono::milliseconds> timeout_of(std::int64_t timeout_ms) {
  return timeout_ms < 0 ? std::nullopt : std::optional(std::chrono::milliseconds(timeout_ms));
}

// The message of an invalid handle given to a *_last_error function.
const char* invalid_handle_message() noexcept;

}  // namespace filigree::c_api
