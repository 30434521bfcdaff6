#pragma once
// Threads kept for short parallel sections that recur every frame (direct
// recovery's partitions): waking a waiting helper costs less than starting
// and joining a thread per frame (on this 2-core VM, 82–85 against 125–129
// µs at the median for a 200 µs section after 1 ms idle, and a shorter
// tail). One team per process, shared by every caller: a caller that finds
// no idle helper runs with fewer threads, so what it computes must not
// depend on how many ran. In a child of fork() (which has none of the
// parent's threads) every crew is the caller alone.

#include <cstddef>
#include <functional>
#include <memory>
#include <vector>

namespace filigree {

class HelperTeam {
 public:
  class Crew;

  // The process's team: one helper per core beyond the first, started on
  // first use, joined at exit.
  static HelperTeam& shared();
  // A team of its own with `helpers` threads (tests; callers share shared()).
  explicit HelperTeam(std::size_t helpers);

  // Up to `wanted` idle helpers, reserved for one run() of the returned crew.
  Crew reserve(std::size_t wanted);

  ~HelperTeam();
  HelperTeam(const HelperTeam&) = delete;
  HelperTeam& operator=(const HelperTeam&) = delete;

 private:
  struct Helper;

  std::vector<std::unique_ptr<Helper>> helpers_;
};

// Helpers reserved for one parallel section; released when it is destroyed.
class HelperTeam::Crew {
 public:
  // Threads a run() uses: the caller and the helpers reserved.
  std::size_t threads() const { return 1 + members_.size(); }
  // Runs fn(0) on the caller and fn(1) … fn(threads() − 1) on the helpers,
  // and returns once every call has returned. fn must not throw. Once per crew.
  void run(const std::function<void(std::size_t)>& fn);

  ~Crew();
  Crew(Crew&&) noexcept = default;
  Crew(const Crew&) = delete;
  Crew& operator=(const Crew&) = delete;
  Crew& operator=(Crew&&) = delete;

 private:
  friend class HelperTeam;
  Crew() = default;
  std::vector<Helper*> members_;
  bool ran_ = false;
};

}  // namespace filigree
