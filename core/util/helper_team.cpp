#include "util/helper_team.h"

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <utility>

#include <pthread.h>

namespace filigree {
namespace {

// A child of fork() has none of its parent's threads: the teams made before
// the fork must not hand out helpers there (a run would wait for ever) nor
// join them at exit. Python's multiprocessing forks by default.
std::atomic<bool> g_forked{false};
void mark_forked() { g_forked.store(true, std::memory_order_relaxed); }

}  // namespace

// One helper: it sleeps until given a job, runs it, and says so by raising
// `finished` to the job's number. The caller waits on `finished`, a member
// that outlives every job (a counter on the caller's stack could be gone
// before the helper's notify touched it). Only the crew that reserved the
// helper writes a job, so it may read `assigned` back without the lock.
struct HelperTeam::Helper {
  std::atomic<bool> reserved{false};
  std::mutex mutex;
  std::condition_variable wake;
  void* fn = nullptr;                             // under mutex: the job, null when none
  void (*call)(void*, std::size_t) = nullptr;     // under mutex
  std::size_t id = 0;                             // under mutex
  std::uint64_t assigned = 0;                     // under mutex: the job's number
  bool stop = false;                              // under mutex
  std::atomic<std::uint64_t> finished{0};
  std::thread thread;

  void loop() {
    std::unique_lock lock(mutex);
    while (true) {
      wake.wait(lock, [&] { return stop || fn != nullptr; });
      if (stop) return;
      void* const job = std::exchange(fn, nullptr);
      const std::size_t my_id = id;
      const std::uint64_t number = assigned;
      lock.unlock();
      call(job, my_id);
      finished.store(number, std::memory_order_release);
      finished.notify_all();
      lock.lock();
    }
  }
};

HelperTeam& HelperTeam::shared() {
  static HelperTeam team(std::max(1u, std::thread::hardware_concurrency()) - 1);
  return team;
}

HelperTeam::HelperTeam(std::size_t helpers) {
  [[maybe_unused]] static const int registered = pthread_atfork(nullptr, nullptr, mark_forked);
  for (std::size_t i = 0; i < helpers; ++i) {
    helpers_.push_back(std::make_unique<Helper>());
    Helper* h = helpers_.back().get();
    h->thread = std::thread([h] { h->loop(); });
  }
}

HelperTeam::~HelperTeam() {
  if (g_forked.load(std::memory_order_relaxed)) {
    for (auto& h : helpers_) (void)h.release();  // the parent's threads: not ours to join
    return;
  }
  for (const auto& h : helpers_) {
    {
      std::lock_guard lock(h->mutex);
      h->stop = true;
    }
    h->wake.notify_one();
    h->thread.join();
  }
}

HelperTeam::Crew HelperTeam::reserve(std::size_t wanted) {
  Crew crew;
  if (g_forked.load(std::memory_order_relaxed)) return crew;
  wanted = std::min(wanted, kMaxCrew);
  for (const auto& h : helpers_) {
    if (crew.size_ >= wanted) break;
    bool idle = false;
    if (h->reserved.compare_exchange_strong(idle, true, std::memory_order_acquire)) crew.members_[crew.size_++] = h.get();
  }
  return crew;
}

void HelperTeam::Crew::run_job(void* fn, void (*call)(void*, std::size_t)) {
  if (std::exchange(ran_, true)) throw std::logic_error("a helper crew runs once");
  for (std::size_t i = 0; i < size_; ++i) {
    Helper& h = *members_[i];
    {
      std::lock_guard lock(h.mutex);
      h.fn = fn;
      h.call = call;
      h.id = i + 1;
      h.assigned = h.finished.load(std::memory_order_relaxed) + 1;
    }
    h.wake.notify_one();
  }
  call(fn, 0);
  for (std::size_t i = 0; i < size_; ++i) {
    const Helper& h = *members_[i];
    for (std::uint64_t seen = h.finished.load(std::memory_order_acquire); seen < h.assigned;
         seen = h.finished.load(std::memory_order_acquire))
      h.finished.wait(seen, std::memory_order_acquire);
  }
}

HelperTeam::Crew::Crew(Crew&& other) noexcept
    : members_(other.members_), size_(std::exchange(other.size_, 0)), ran_(other.ran_) {}

HelperTeam::Crew::~Crew() {
  for (std::size_t i = 0; i < size_; ++i) members_[i]->reserved.store(false, std::memory_order_release);
}

}  // namespace filigree
