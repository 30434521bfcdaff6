// The client library's channel settings for frames (filigree/channel_arguments.h).

#include <optional>
#include <string>

#include <grpc/grpc.h>
#include <gtest/gtest.h>

#include "filigree/channel_arguments.h"

namespace filigree {
namespace {

// The integer argument `key`, or nothing if it is not set.
std::optional<int> int_argument(const grpc::ChannelArguments& args, const std::string& key) {
  const grpc_channel_args c = args.c_channel_args();
  for (std::size_t i = 0; i < c.num_args; ++i)
    if (key == c.args[i].key && c.args[i].type == GRPC_ARG_INTEGER) return c.args[i].value.integer;
  return std::nullopt;
}

TEST(ChannelArguments, FramesGetAFixedWindowAndNoSizeLimit) {
  const grpc::ChannelArguments args = frame_channel_arguments();
  // gRPC ignores the lookahead while BDP probing is on: both are needed.
  EXPECT_EQ(int_argument(args, GRPC_ARG_HTTP2_BDP_PROBE), 0);
  EXPECT_EQ(int_argument(args, GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES), kFrameStreamWindowBytes);
  // A keyframe of 1.25M vertices (~1.2 MiB) fits in one window, and a slow
  // watcher's stale frames stay within what gRPC's own window let through.
  EXPECT_GE(kFrameStreamWindowBytes, 2 << 20);
  EXPECT_LE(kFrameStreamWindowBytes, 4 << 20);
  EXPECT_EQ(int_argument(args, GRPC_ARG_MAX_RECEIVE_MESSAGE_LENGTH), -1);
}

}  // namespace
}  // namespace filigree
