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
// before the helper's notify touched it).
struct HelperTeam::Helper {
  std::atomic<bool> reserved{false};
  std::mutex mutex;
  std::condition_variable wake;
  const std::function<void(std::size_t)>* job = nullptr;  // under mutex
  std::size_t id = 0;                                      // under mutex
  std::uint64_t assigned = 0;                              // under mutex: the job's number
  bool stop = false;                                       // under mutex
  std::atomic<std::uint64_t> finished{0};
  std::thread thread;

  void loop() {
    std::unique_lock lock(mutex);
    while (true) {
      wake.wait(lock, [&] { return stop || job != nullptr; });
      if (stop) return;
      const auto* fn = std::exchange(job, nullptr);
      const std::size_t my_id = id;
      const std::uint64_t number = assigned;
      lock.unlock();
      (*fn)(my_id);
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
  for (const auto& h : helpers_) {
    if (crew.members_.size() >= wanted) break;
    bool idle = false;
    if (h->reserved.compare_exchange_strong(idle, true, std::memory_order_acquire)) crew.members_.push_back(h.get());
  }
  return crew;
}

void HelperTeam::Crew::run(const std::function<void(std::size_t)>& fn) {
  if (std::exchange(ran_, true)) throw std::logic_error("a helper crew runs once");
  std::vector<std::uint64_t> numbers(members_.size());
  for (std::size_t i = 0; i < members_.size(); ++i) {
    Helper& h = *members_[i];
    {
      std::lock_guard lock(h.mutex);
      h.job = &fn;
      h.id = i + 1;
      numbers[i] = h.assigned = h.finished.load(std::memory_order_relaxed) + 1;
    }
    h.wake.notify_one();
  }
  fn(0);
  for (std::size_t i = 0; i < members_.size(); ++i) {
    const std::atomic<std::uint64_t>& finished = members_[i]->finished;
    for (std::uint64_t seen = finished.load(std::memory_order_acquire); seen < numbers[i];
         seen = finished.load(std::memory_order_acquire))
      finished.wait(seen, std::memory_order_acquire);
  }
}

HelperTeam::Crew::~Crew() {
  for (Helper* h : members_) h->reserved.store(false, std::memory_order_release);
}

}  // namespace filigree
