#pragma once
// The channel settings a Filigree client needs to receive frames at the
// speed they are made.

#include <grpcpp/support/channel_arguments.h>

namespace filigree {

// HTTP/2 receive window per stream for frames: fixed, 4 MiB. A keyframe of
// 1.25M vertices (~1.2 MiB) arrives without waiting for a window update, and
// a Watch reader slower than the session reads at most this much of stale
// frames before the server's mailbox of one takes over (about what gRPC's
// adaptive window let through; a viewer that wants less sets a smaller one).
inline constexpr int kFrameStreamWindowBytes = 4 << 20;

// No limit on received message size (a SessionInfo of a 1M-vertex mesh is
// ~36 MiB, over gRPC's 4 MiB default), and the fixed window above instead of
// gRPC's adaptive (BDP) one, which on loopback stays near 64 KiB for a
// ping-pong of large messages: the server's write of a 1.25M-vertex frame
// (~0.9 MiB) then waits on ~15 window updates (StartWrite 5.5 ms median
// here, against 0.8 ms with a fixed window; the frame reaches the client
// 2.7 ms after it is offered instead of 5.7). Other clients should set the
// same (grpc-js: 'grpc-node.flow_control_window'; gRPC core and grpcio:
// 'grpc.http2.bdp_probe' 0 and 'grpc.http2.lookahead_bytes').
grpc::ChannelArguments frame_channel_arguments();

}  // namespace filigree
