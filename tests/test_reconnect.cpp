// ReconnectSchedule (client/lib/include/filigree/reconnect.h): which ends of a
// stream are retried, and with what status a stream ends for good, the
// client's cancel included. No server: the schedule sees statuses only.

#include "filigree/reconnect.h"

#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <optional>

namespace filigree {
namespace {

struct Ending {
  std::optional<grpc::Status> status;
  int reconnects = 0;
};

// One wait_to_reconnect after `why`, the client having cancelled or not;
// no backoff, so that a retry returns at once.
Ending after(const grpc::Status& why, bool cancelled, bool enabled = true) {
  Ending out;
  Reconnect policy;
  policy.enabled = enabled;
  policy.first_backoff = policy.max_backoff = std::chrono::milliseconds(0);
  policy.on_reconnect = [&](const grpc::Status&, int attempt) { out.reconnects = attempt; };
  ReconnectSchedule schedule(policy);
  std::mutex mutex;
  std::condition_variable cv;
  const bool flag = cancelled;
  out.status = schedule.wait_to_reconnect(why, mutex, cv, flag);
  return out;
}

TEST(ReconnectSchedule, AnOutageIsRetriedUnlessTheClientCancelled) {
  for (const auto code : {grpc::StatusCode::UNAVAILABLE, grpc::StatusCode::INTERNAL, grpc::StatusCode::CANCELLED}) {
    const Ending retried = after(grpc::Status(code, "gone"), false);
    EXPECT_FALSE(retried.status.has_value()) << code;
    EXPECT_EQ(retried.reconnects, 1) << code;
    // Cancelled by the client: that is why it ended.
    const Ending cancelled = after(grpc::Status(code, "gone"), true);
    ASSERT_TRUE(cancelled.status.has_value()) << code;
    EXPECT_EQ(cancelled.status->error_code(), grpc::StatusCode::CANCELLED) << code;
    EXPECT_EQ(cancelled.reconnects, 0) << code;
  }
}

TEST(ReconnectSchedule, WhatTheServerSaidEndsTheStreamEvenAfterACancel) {
  for (bool cancelled : {false, true}) {
    for (const auto code : {grpc::StatusCode::NOT_FOUND, grpc::StatusCode::PERMISSION_DENIED,
                            grpc::StatusCode::INVALID_ARGUMENT, grpc::StatusCode::OK}) {
      const Ending e = after(grpc::Status(code, code == grpc::StatusCode::OK ? "" : "said"), cancelled);
      ASSERT_TRUE(e.status.has_value()) << code;
      EXPECT_EQ(e.status->error_code(), code) << code << (cancelled ? " after a cancel" : "");
      EXPECT_EQ(e.reconnects, 0);
    }
  }
}

TEST(ReconnectSchedule, WithoutReconnectionAnOutageEndsTheStreamAsItCame) {
  const Ending e = after(grpc::Status(grpc::StatusCode::UNAVAILABLE, "gone"), false, /*enabled=*/false);
  ASSERT_TRUE(e.status.has_value());
  EXPECT_EQ(e.status->error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_EQ(e.status->error_message(), "gone");
  EXPECT_EQ(e.reconnects, 0);
}

}  // namespace
}  // namespace filigree
