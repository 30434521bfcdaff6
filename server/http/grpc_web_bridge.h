#pragma once
// gRPC-Web (binary: application/grpc-web, application/grpc-web+proto) in
// front of the in-process gRPC server, the way Envoy's grpc_web filter does
// it: one implementation of the service, reached through a generic stub on
// grpc::Server::InProcessChannel, with raw ByteBuffers (no knowledge of
// message types).
//
// Wire format (grpc/grpc doc/PROTOCOL-WEB.md): the request body is one
// length-prefixed frame (flag 0x00, 4-byte big-endian length, message); the
// response body is data frames (flag 0x00) and then exactly one trailer frame
// (flag 0x80) whose payload is HTTP/1 header lines "grpc-status:N\r\n",
// "grpc-message:<percent-encoded>\r\n", plus any trailing metadata. Request
// metadata arrives as HTTP headers (x-filigree-token, x-session-id,
// grpc-timeout). Only unary and server-streaming methods can be called from
// browsers; client- and bidi-streaming ones answer UNIMPLEMENTED.
//
// Not HTTP: this file knows neither sockets nor Beast. The HTTP server hands
// it a request and gets the response body back as frames, through callbacks.

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <set>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <grpcpp/channel.h>
#include <grpcpp/support/status.h>
#include <grpcpp/support/string_ref.h>

namespace filigree::server::http {

// ------------------------------------------------------------ framing

inline constexpr std::uint8_t kDataFrame = 0x00;
inline constexpr std::uint8_t kTrailerFrame = 0x80;
inline constexpr std::string_view kGrpcWebContentType = "application/grpc-web+proto";

// flag byte, 4-byte big-endian length, payload.
std::string encode_frame(std::uint8_t flags, std::string_view payload);

// The trailer frame for a final status: grpc-status, grpc-message (if any,
// percent-encoded), grpc-status-details-bin (if any, base64) and `metadata`
// (the server's trailing metadata; "-bin" values base64-encoded).
std::string encode_trailer_frame(const grpc::Status& status,
                                 const std::multimap<grpc::string_ref, grpc::string_ref>& metadata = {});

// grpc-message encoding (gRPC over HTTP/2 spec): bytes outside 0x20–0x7E and
// '%' become %XX.
std::string percent_encode(std::string_view message);

// A request body is one or more uncompressed data frames, back to back.
// Returns OK and the messages (views into `body`), or INVALID_ARGUMENT
// (UNIMPLEMENTED for a compressed frame).
grpc::Status parse_request_body(std::string_view body, std::vector<std::string_view>* messages);

// "grpc-timeout" (1–8 digits and a unit H M S m u n); nullopt when malformed.
std::optional<std::chrono::nanoseconds> parse_grpc_timeout(std::string_view value);

// application/grpc-web or application/grpc-web+proto (parameters and case ignored).
bool is_grpc_web_binary(std::string_view content_type);

// ------------------------------------------------------------ calls

// A call in flight. Both methods may be called from any thread, at any time,
// also after the call ended (then they do nothing).
class GrpcWebCall {
 public:
  virtual ~GrpcWebCall() = default;
  // The last data frame has been written: deliver the next one. Flow control
  // for streams: the upstream is read no faster than the browser takes it
  // (the service's mailbox of one then skips frames for a slow browser).
  virtual void read_more() = 0;
  // The browser is gone: cancel the upstream call. on_end still follows.
  virtual void cancel() = 0;
};

// Called on gRPC threads, never two at once, never inline from start().
struct GrpcWebEvents {
  // One data frame (flag, length, message). No further on_data before read_more().
  std::function<void(std::string frame)> on_data;
  // The trailer frame: always the last event, exactly once.
  std::function<void(std::string frame)> on_end;
};

struct GrpcWebRequest {
  std::string path;  // "/filigree.v1.Filigree/Watch"
  std::string content_type;
  // Shared: a request-streaming call's messages are written from it in
  // place, without a copy (an upload's body is the mesh).
  std::shared_ptr<const std::string> body;
  std::vector<std::pair<std::string, std::string>> headers;  // lower-case names
};

class GrpcWebBridge {
 public:
  // `services`: full names of the services exposed ("filigree.v1.Filigree");
  // their methods are looked up in the generated protobuf descriptor pool
  // (throws std::invalid_argument for an unknown service).
  // `route` (may be empty): the channel for a session's calls, or nullptr
  // for `channel` (replicas: the one that serves the session).
  // `request_streams`: paths of request-streaming methods served all the
  // same, from a body of several length-prefixed messages sent in order
  // before the half-close (gRPC-Web has no request streaming; an upload is
  // its messages at once: "/filigree.v1.Filigree/CreateSession").
  GrpcWebBridge(std::shared_ptr<grpc::Channel> channel, const std::vector<std::string>& services,
                std::function<std::shared_ptr<grpc::Channel>(const std::string&)> route = {},
                std::vector<std::string> request_streams = {});
  // Cancels the calls still running and waits for them (bounded).
  ~GrpcWebBridge();
  GrpcWebBridge(const GrpcWebBridge&) = delete;
  GrpcWebBridge& operator=(const GrpcWebBridge&) = delete;

  struct Started {
    // Null: the request was refused before any call (unknown or streaming-request
    // method, malformed body or metadata); `immediate` is the whole response
    // body, a single trailer frame.
    std::shared_ptr<GrpcWebCall> call;
    bool server_streaming = false;
    std::string immediate;
  };
  // The response body is always HTTP 200 with content type kGrpcWebContentType.
  Started start(const GrpcWebRequest& request, GrpcWebEvents events);

  // The trailer frame for a request whose body is over the HTTP server's limit.
  static std::string too_large(std::size_t limit);

  // Cancels every call in flight (shutdown).
  void cancel_all();
  // Waits until no call is in flight; false on timeout.
  bool wait_idle(std::chrono::steady_clock::time_point deadline);

  struct Inflight;  // shared with the calls, which may outlive the bridge

 private:
  enum class Kind { kUnary, kServerStreaming, kClientStreaming, kBidiStreaming };
  std::shared_ptr<grpc::Channel> channel_;
  std::function<std::shared_ptr<grpc::Channel>(const std::string&)> route_;
  std::set<std::string, std::less<>> request_streams_;
  std::map<std::string, Kind, std::less<>> methods_;  // "/pkg.Service/Method"
  std::shared_ptr<Inflight> inflight_;
};

}  // namespace filigree::server::http
