#pragma once
// The channel settings a Filigree client needs to receive frames at the
// speed they are made.

#include <grpcpp/support/channel_arguments.h>

namespace filigree {

// HTTP/2 stream window for frames: fixed, 16 MiB.
inline constexpr int kFrameStreamWindowBytes = 16 << 20;

// No limit on received message size (a SessionInfo of a 1M-vertex mesh is
// ~36 MiB, over gRPC's 4 MiB default), and a fixed kFrameStreamWindowBytes
// receive window per stream instead of gRPC's adaptive (BDP) one, which on
// loopback stays near 64 KiB for a ping-pong of large messages: the server's
// write of a 1.25M-vertex frame (~0.9 MiB) then waits on ~15 window updates
// (5.5 ms median here, against 0.8 ms with this window; the frame reaches
// the client 2.7 ms after it is offered instead of 5.7). The server writes
// one frame at a time per stream, so the window never holds more than a
// frame and the keyframe before it. Other clients should set the same
// (grpc-js: 'grpc-node.flow_control_window'; grpcio: 'grpc.http2.bdp_probe'
// 0 and 'grpc.http2.lookahead_bytes').
grpc::ChannelArguments frame_channel_arguments();

}  // namespace filigree
