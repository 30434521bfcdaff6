#pragma once
// Scratch buffers shared by owners that each need one only for a while (a
// session between computing a frame and quantizing it, a frame chunk between
// quantizing and encoding): an idle owner then holds none, and a busy steady
// state allocates nothing, since buffers go round, however many owners are
// busy at once. Thread-safe.
//
// How many it keeps follows demand: as many buffers, in use and free, as
// were in use at once lately (at least `min_free` free ones). A fixed bound
// below the number of busy owners made most frames allocate and fault in a
// mesh-sized buffer (8 sessions of a 151k mesh ran at 0.48–0.75 of the rate).
// Demand is measured in takes, so a pool nobody uses would keep its last
// peak: trim_if_idle(), called now and then, drops it back to the minimum.

#include <algorithm>
#include <cstddef>
#include <mutex>
#include <utility>
#include <vector>

namespace filigree {

template <class T>
class BufferPool {
 public:
  // Keeps at least `min_free` buffers between uses; see above for more.
  explicit BufferPool(std::size_t min_free) : min_free_(min_free) { free_.reserve(min_free_); }
  BufferPool(const BufferPool&) = delete;
  BufferPool& operator=(const BufferPool&) = delete;

  // A buffer of `size` elements, contents unspecified: the free one with the
  // least capacity that holds `size` (no reallocation), else a new one.
  std::vector<T> take(std::size_t size) {
    std::vector<T> buffer;
    std::vector<std::vector<T>> surplus;  // freed outside the lock
    {
      std::lock_guard lock(mutex_);
      auto best = free_.end();
      for (auto it = free_.begin(); it != free_.end(); ++it)
        if (it->capacity() >= size && (best == free_.end() || it->capacity() < best->capacity())) best = it;
      if (best != free_.end()) {
        buffer = std::move(*best);
        free_.erase(best);
      }
      peak_ = std::max(peak_, ++in_use_);
      if (++takes_ % kEpochTakes == 0) {
        // Demand is the peak of this epoch and the last: older peaks expire,
        // and buffers beyond them go (outside the lock).
        previous_peak_ = std::exchange(peak_, in_use_);
        take_surplus(surplus);
      }
    }
    buffer.resize(size);
    return buffer;
  }

  // Returns a buffer (normally one take() gave) for later take()s; an empty
  // one is ignored. Never throws: callers give back from destructors and
  // from paths that must not fail, so a buffer that finds no reserved room
  // is freed rather than kept.
  void give(std::vector<T>&& buffer) noexcept {
    if (buffer.capacity() == 0) return;
    std::vector<T> dropped;  // freed outside the lock
    std::lock_guard lock(mutex_);
    if (in_use_ > 0) --in_use_;
    if (free_.size() == free_.capacity()) reserve_room();
    if (in_use_ + free_.size() < bound() && free_.size() < free_.capacity()) {
      free_.push_back(std::move(buffer));
    } else {
      dropped = std::move(buffer);
    }
  }

  // Called periodically (the server's maintenance loop): when no take came
  // since the previous call, the pool is idle, and free buffers beyond
  // `min_free` go (a busy pool is left alone). Returns how many went.
  std::size_t trim_if_idle() {
    std::vector<std::vector<T>> surplus;  // freed outside the lock
    std::lock_guard lock(mutex_);
    if (std::exchange(takes_at_trim_, takes_) != takes_) return 0;
    peak_ = previous_peak_ = in_use_;
    take_surplus(surplus);
    return surplus.size();
  }

  std::size_t free_buffers() const {
    std::lock_guard lock(mutex_);
    return free_.size();
  }

  // Takes between two updates of the demand estimate.
  static constexpr std::size_t kEpochTakes = 64;

 private:
  // Buffers worth owning, in use and free (mutex_ held).
  std::size_t bound() const { return std::max(in_use_ + min_free_, std::max(peak_, previous_peak_)); }
  // Moves free buffers beyond bound() into `surplus`, for the caller to free
  // outside the lock (mutex_ held).
  void take_surplus(std::vector<std::vector<T>>& surplus) {
    while (!free_.empty() && in_use_ + free_.size() > bound()) {
      surplus.push_back(std::move(free_.back()));
      free_.pop_back();
    }
  }
  // Room for one more free buffer; if that allocation fails, give() frees
  // the buffer instead of throwing.
  void reserve_room() noexcept {
    try {
      free_.reserve(2 * free_.capacity() + 1);
    } catch (...) {
    }
  }

  const std::size_t min_free_;
  mutable std::mutex mutex_;
  std::vector<std::vector<T>> free_;
  std::size_t in_use_ = 0;  // taken, not yet given back
  std::size_t peak_ = 0, previous_peak_ = 0;  // most in use at once, this epoch and the last
  std::size_t takes_ = 0, takes_at_trim_ = 0;
};

}  // namespace filigree
