#pragma once
// Threads kept for short parallel sections that recur every frame (direct
// recovery's partitions): waking a waiting helper costs less than starting
// and joining a thread per frame (on this 2-core VM, 82–85 against 125–129
// µs at the median for a 200 µs section after 1 ms idle, and a shorter
// tail). One team per process, shared by every caller: a caller that finds
// no idle helper runs with fewer threads, so what it computes must not
// depend on how many ran. In a child of fork() (which has none of the
// parent's threads) every crew is the caller alone.

#include <array>
#include <cstddef>
#include <memory>
#include <type_traits>
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

  // A crew holds at most this many helpers (direct recovery asks for at
  // most kMaxPartitions − 1 = 7): fixed room, so a frame's run allocates
  // nothing.
  static constexpr std::size_t kMaxCrew = 15;

  // Up to min(wanted, kMaxCrew) idle helpers, reserved for one run() of the
  // returned crew.
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
  std::size_t threads() const { return 1 + size_; }
  // Runs fn(0) on the caller and fn(1) … fn(threads() − 1) on the helpers,
  // and returns once every call has returned. fn must not throw. Once per
  // crew. fn is called through a pointer, not copied (no allocation).
  template <class Fn>
  void run(Fn&& fn) {
    using F = std::remove_reference_t<Fn>;
    run_job(const_cast<void*>(static_cast<const void*>(&fn)), [](void* f, std::size_t id) { (*static_cast<F*>(f))(id); });
  }

  ~Crew();
  Crew(Crew&& other) noexcept;
  Crew(const Crew&) = delete;
  Crew& operator=(const Crew&) = delete;
  Crew& operator=(Crew&&) = delete;

 private:
  friend class HelperTeam;
  Crew() = default;
  void run_job(void* fn, void (*call)(void*, std::size_t));
  std::array<Helper*, kMaxCrew> members_{};
  std::size_t size_ = 0;
  bool ran_ = false;
};

}  // namespace filigree
