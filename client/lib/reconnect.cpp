#include "filigree/reconnect.h"

#include <algorithm>

namespace filigree {

std::chrono::milliseconds ReconnectSchedule::next(const grpc::Status& status, bool cancelled_by_us) {
  constexpr std::chrono::milliseconds kEnd{-1};
  // The server went away, not the session: UNAVAILABLE; CANCELLED that this
  // client did not ask for (a server shutting down); INTERNAL, which is how a
  // proxy's reset shows when the replica behind it dies ("Received RST_STREAM
  // with error code 2") and which the service never ends a stream with.
  // A client that cancelled wants no further attempt (nor on_reconnect).
  const grpc::StatusCode code = status.error_code();
  const bool gone = code == grpc::StatusCode::UNAVAILABLE || code == grpc::StatusCode::INTERNAL ||
                    code == grpc::StatusCode::CANCELLED;
  if (!policy_.enabled || !gone || cancelled_by_us) return kEnd;
  const auto now = std::chrono::steady_clock::now();
  if (attempt_ == 0) {
    backoff_ = policy_.first_backoff;
    give_up_at_ = now + policy_.give_up_after;
  }
  if (now >= give_up_at_) return kEnd;
  ++attempt_;
  if (policy_.on_reconnect) policy_.on_reconnect(status, attempt_);
  const std::chrono::milliseconds wait = backoff_;
  backoff_ = std::min(backoff_ * 2, policy_.max_backoff);
  return wait;
}

std::optional<grpc::Status> ReconnectSchedule::wait_to_reconnect(const grpc::Status& status, std::mutex& mutex,
                                                                 std::condition_variable& cv, const bool& cancelled) {
  // The client's cancel is why the stream ended only when the status is one
  // a cancel or an outage makes; a status the server chose (NOT_FOUND, …)
  // stays, even if a cancel came after it.
  const grpc::StatusCode code = status.error_code();
  const bool outage = code == grpc::StatusCode::UNAVAILABLE || code == grpc::StatusCode::INTERNAL ||
                      code == grpc::StatusCode::CANCELLED;
  const auto end = [&](bool by_us) { return by_us && outage ? grpc::Status::CANCELLED : status; };
  bool by_us;
  {
    std::lock_guard lock(mutex);
    by_us = cancelled;
  }
  const std::chrono::milliseconds wait = next(status, by_us);  // calls on_reconnect: not under the lock
  if (wait.count() < 0) return end(by_us);
  std::unique_lock lock(mutex);
  if (cv.wait_for(lock, wait, [&] { return cancelled; })) return end(true);
  return std::nullopt;
}

}  // namespace filigree
