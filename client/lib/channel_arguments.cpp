#include "filigree/channel_arguments.h"

#include <grpc/grpc.h>

namespace filigree {

grpc::ChannelArguments frame_channel_arguments() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(-1);
  // With BDP probing on, gRPC ignores the lookahead (grpc/grpc#14252).
  args.SetInt(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  args.SetInt(GRPC_ARG_HTTP2_STREAM_LOOKAHEAD_BYTES, kFrameStreamWindowBytes);
  return args;
}

}  // namespace filigree
