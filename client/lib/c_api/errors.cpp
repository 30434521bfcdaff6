// Status codes, error messages, the handle registry and the buffer rules of
// the C API.

#include <cstring>
#include <unordered_map>

#include "c_api/internal.h"

#ifndef FILIGREE_VERSION
#error "FILIGREE_VERSION must be defined by the build (client/lib/CMakeLists.txt)"
#endif

namespace filigree::c_api {
namespace {

struct Registry {
  std::mutex mutex;
  std::unordered_map<const void*, Kind> live;
};

Registry& registry() {
  // Never destroyed: a garbage collector may free handles while the process
  // exits, after static destructors would have run.
  static Registry* r = new Registry;
  return *r;
}

// The calling thread's last failure (filigree_last_error).
thread_local std::string t_last_error;

}  // namespace

void register_handle(const void* handle, Kind kind) {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  r.live[handle] = kind;
}

bool unregister_handle(const void* handle, Kind kind) {
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  const auto it = r.live.find(handle);
  if (it == r.live.end() || it->second != kind) return false;
  r.live.erase(it);
  return true;
}

bool is_handle(const void* handle, Kind kind) {
  if (!handle) return false;
  Registry& r = registry();
  std::lock_guard lock(r.mutex);
  const auto it = r.live.find(handle);
  return it != r.live.end() && it->second == kind;
}

void ErrorSlot::set(std::string_view message) noexcept {
  std::lock_guard lock(mutex_);
  try {
    message_.assign(message);
  } catch (...) {  // out of memory: keep the previous message rather than throw into C
  }
}

const char* ErrorSlot::get() const noexcept {
  std::lock_guard lock(mutex_);
  return message_.c_str();
}

int fail(ErrorSlot* slot, int status, std::string_view message) noexcept {
  try {
    t_last_error.assign(message);
  } catch (...) {
  }
  if (slot) slot->set(message);
  return status;
}

int status_of(grpc::StatusCode code) {
  const int n = static_cast<int>(code);
  return n >= 0 && n <= FILIGREE_UNAUTHENTICATED ? n : FILIGREE_UNKNOWN;
}

int null_argument(ErrorSlot* slot, const char* function, const char* argument) noexcept {
  try {
    return fail(slot, FILIGREE_ERROR_NULL_ARGUMENT, std::string(function) + ": `" + argument + "` is NULL");
  } catch (...) {
    return fail(slot, FILIGREE_ERROR_NULL_ARGUMENT, "an argument is NULL");
  }
}

int copy_out(ErrorSlot* slot, const char* function, const void* data, std::size_t count, std::size_t element_size,
             void* buffer, std::size_t capacity, std::size_t* required) noexcept {
  if (required) *required = count;
  if (!buffer && capacity > 0) return null_argument(slot, function, "buffer");
  if (capacity < count) {
    try {
      return fail(slot, FILIGREE_ERROR_BUFFER_TOO_SMALL,
                  std::string(function) + ": the buffer holds " + std::to_string(capacity) + " elements, " +
                      std::to_string(count) + " are needed");
    } catch (...) {
      return fail(slot, FILIGREE_ERROR_BUFFER_TOO_SMALL, "buffer too small");
    }
  }
  if (count > 0) std::memcpy(buffer, data, count * element_size);
  return FILIGREE_OK;
}

int copy_string(ErrorSlot* slot, const char* function, const std::string& s, char* buffer, std::size_t capacity,
                std::size_t* required) noexcept {
  return copy_out(slot, function, s.c_str(), s.size() + 1, 1, buffer, capacity, required);
}

const char* invalid_handle_message() noexcept {
  return "not a live handle of this kind (NULL, freed, or another kind of handle)";
}

}  // namespace filigree::c_api

using namespace filigree::c_api;

extern "C" {

const char* filigree_status_name(int status) {
  switch (status) {
    case FILIGREE_OK: return "OK";
    case FILIGREE_CANCELLED: return "CANCELLED";
    case FILIGREE_UNKNOWN: return "UNKNOWN";
    case FILIGREE_INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case FILIGREE_DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case FILIGREE_NOT_FOUND: return "NOT_FOUND";
    case FILIGREE_ALREADY_EXISTS: return "ALREADY_EXISTS";
    case FILIGREE_PERMISSION_DENIED: return "PERMISSION_DENIED";
    case FILIGREE_RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case FILIGREE_FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case FILIGREE_ABORTED: return "ABORTED";
    case FILIGREE_OUT_OF_RANGE: return "OUT_OF_RANGE";
    case FILIGREE_UNIMPLEMENTED: return "UNIMPLEMENTED";
    case FILIGREE_INTERNAL: return "INTERNAL";
    case FILIGREE_UNAVAILABLE: return "UNAVAILABLE";
    case FILIGREE_DATA_LOSS: return "DATA_LOSS";
    case FILIGREE_UNAUTHENTICATED: return "UNAUTHENTICATED";
    case FILIGREE_ERROR_INVALID_HANDLE: return "ERROR_INVALID_HANDLE";
    case FILIGREE_ERROR_BUFFER_TOO_SMALL: return "ERROR_BUFFER_TOO_SMALL";
    case FILIGREE_ERROR_NULL_ARGUMENT: return "ERROR_NULL_ARGUMENT";
    case FILIGREE_ERROR_OUT_OF_MEMORY: return "ERROR_OUT_OF_MEMORY";
    case FILIGREE_ERROR_STREAM_ENDED: return "ERROR_STREAM_ENDED";
    case FILIGREE_ERROR_WRONG_THREAD: return "ERROR_WRONG_THREAD";
    default: return "UNKNOWN_STATUS";
  }
}

const char* filigree_version_string(void) { return FILIGREE_VERSION; }

const char* filigree_last_error(void) { return t_last_error.c_str(); }

}  // extern "C"
