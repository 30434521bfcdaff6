#pragma once
// How a stream (Watcher, Driver) outlives a server restart, a replica going
// away or a session moving.

#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <optional>

#include <grpcpp/support/status.h>

namespace filigree {

// After UNAVAILABLE (or a CANCELLED the client did not ask for: a server
// shutting down cancels its calls; or INTERNAL: a proxy resetting the stream
// when the replica behind it dies) the stream reopens itself, waiting a
// backoff before each attempt. A Watch resumes after the last version it
// delivered (the server sends the keyframe the next frame needs first); a
// Drive re-sends the poses no frame has acknowledged yet.
struct Reconnect {
  bool enabled = true;
  std::chrono::milliseconds first_backoff{100};  // doubles after each failed attempt…
  std::chrono::milliseconds max_backoff{2000};   // …up to this
  std::chrono::milliseconds give_up_after{60000};  // then the stream ends with the last status
  // Called on the reading thread before each attempt: why the stream ended
  // and the attempt's number (1, 2, …; back to 1 after a frame arrived).
  // This is where an engine learns that its stream is recovering.
  std::function<void(const grpc::Status& why, int attempt)> on_reconnect;
};

// The attempts of one stream: which ends are worth another attempt, and how
// long to wait before it. Not thread-safe: used by the reading thread.
class ReconnectSchedule {
 public:
  explicit ReconnectSchedule(Reconnect policy = {}) : policy_(std::move(policy)) {}

  // After `status` ended the stream: whether to try again (on_reconnect is
  // called), then the backoff: a wait that a cancel ends at once (`cancelled`
  // is read under `mutex`; the canceller sets it under `mutex` and notifies
  // `cv`). nullopt: reopen the stream now. Else the stream ends for good,
  // with this status: CANCELLED when the client cancelled (before or during
  // the wait) a stream that ended UNAVAILABLE, INTERNAL or CANCELLED, as the
  // cancel is why it ended; else `status` (OK, or what the server said).
  std::optional<grpc::Status> wait_to_reconnect(const grpc::Status& status, std::mutex& mutex, std::condition_variable& cv,
                                                const bool& cancelled);
  // A frame arrived: the next failure starts over at first_backoff.
  void reset() { attempt_ = 0; }
  void disable() { policy_.enabled = false; }
  bool enabled() const { return policy_.enabled; }

 private:
  // After `status` ended the stream: the wait before the next attempt (and
  // on_reconnect called), or a negative duration when the stream ends for
  // good: reconnection off, a status that is not the server going away
  // (`cancelled_by_us`: the client cancelled), or give_up_after passed.
  std::chrono::milliseconds next(const grpc::Status& status, bool cancelled_by_us);

  Reconnect policy_;
  int attempt_ = 0;
  std::chrono::milliseconds backoff_{0};
  std::chrono::steady_clock::time_point give_up_at_{};
};

}  // namespace filigree
