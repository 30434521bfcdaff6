#pragma once
// A barrier for a few threads that each run on a core of their own between
// short phases (direct recovery's, ~0.1–1 ms apart): a thread that arrives
// early spins for a while before it sleeps. std::barrier sleeps at once, and
// waking a thread costs tens of microseconds in a VM, per phase.

#include <atomic>
#include <cstdint>

namespace filigree {

class SpinBarrier {
 public:
  // `threads` ≥ 1 take part in every phase.
  explicit SpinBarrier(std::uint32_t threads) : threads_(threads) {}
  SpinBarrier(const SpinBarrier&) = delete;
  SpinBarrier& operator=(const SpinBarrier&) = delete;

  // Returns once every thread has arrived in this phase. Whatever a thread
  // wrote before arriving is visible to every thread after it returns.
  void arrive_and_wait() {
    const std::uint32_t phase = phase_.load(std::memory_order_acquire);
    if (arrived_.fetch_add(1, std::memory_order_acq_rel) + 1 == threads_) {
      // The others only read arrived_ again after they see the new phase.
      arrived_.store(0, std::memory_order_relaxed);
      phase_.fetch_add(1, std::memory_order_acq_rel);
      phase_.notify_all();
      return;
    }
    for (int spin = 0; spin < kSpins; ++spin) {
      if (phase_.load(std::memory_order_acquire) != phase) return;
      pause();
    }
    while (phase_.load(std::memory_order_acquire) == phase) phase_.wait(phase, std::memory_order_acquire);
  }

 private:
  // Tens of microseconds of spinning before sleeping (a pause takes 10–150
  // cycles, by processor): longer than a wake-up costs, short enough that a
  // partner descheduled for another process wastes little.
  static constexpr int kSpins = 2048;
  static void pause() {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#endif
  }

  const std::uint32_t threads_;
  std::atomic<std::uint32_t> arrived_{0};
  std::atomic<std::uint32_t> phase_{0};
};

}  // namespace filigree
