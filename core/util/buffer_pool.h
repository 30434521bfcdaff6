#pragma once
// Scratch buffers shared by owners that each need one only for a while (a
// session between computing a frame and quantizing it, a frame chunk between
// quantizing and encoding): an idle owner then holds none, and a busy steady
// state allocates nothing, since buffers go round. Thread-safe.

#include <algorithm>
#include <cstddef>
#include <mutex>
#include <vector>

namespace filigree {

template <class T>
class BufferPool {
 public:
  // Keeps at most `max_free` buffers between uses; more given back are freed.
  explicit BufferPool(std::size_t max_free) : max_free_(max_free) { free_.reserve(max_free_); }
  BufferPool(const BufferPool&) = delete;
  BufferPool& operator=(const BufferPool&) = delete;

  // A buffer of `size` elements, contents unspecified: the free one with the
  // least capacity that holds `size` (no reallocation), else a new one.
  std::vector<T> take(std::size_t size) {
    std::vector<T> buffer;
    {
      std::lock_guard lock(mutex_);
      auto best = free_.end();
      for (auto it = free_.begin(); it != free_.end(); ++it)
        if (it->capacity() >= size && (best == free_.end() || it->capacity() < best->capacity())) best = it;
      if (best != free_.end()) {
        buffer = std::move(*best);
        free_.erase(best);
      }
    }
    buffer.resize(size);
    return buffer;
  }

  // Returns a buffer for later take()s (an empty one is ignored). Never
  // throws (room for max_free buffers is reserved): callers give back from
  // destructors and from paths that must not fail.
  void give(std::vector<T>&& buffer) noexcept {
    if (buffer.capacity() == 0) return;
    std::vector<T> dropped;  // freed outside the lock
    std::lock_guard lock(mutex_);
    if (free_.size() < max_free_) {
      free_.push_back(std::move(buffer));
    } else {
      dropped = std::move(buffer);
    }
  }

  std::size_t free_buffers() const {
    std::lock_guard lock(mutex_);
    return free_.size();
  }

 private:
  const std::size_t max_free_;
  mutable std::mutex mutex_;
  std::vector<std::vector<T>> free_;
};

}  // namespace filigree
