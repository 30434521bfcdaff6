#include "server/http/grpc_web_bridge.h"

#include <algorithm>
#include <cctype>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <unordered_map>

#include <google/protobuf/descriptor.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <spdlog/spdlog.h>

namespace filigree::server::http {
namespace {

constexpr std::size_t kFrameHeader = 5;

std::string base64(std::string_view in) {
  static constexpr char kAlphabet[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((in.size() + 2) / 3 * 4);
  std::size_t i = 0;
  for (; i + 2 < in.size(); i += 3) {
    const std::uint32_t v = (std::uint8_t(in[i]) << 16) | (std::uint8_t(in[i + 1]) << 8) | std::uint8_t(in[i + 2]);
    for (int s : {18, 12, 6, 0}) out += kAlphabet[(v >> s) & 63];
  }
  if (i + 1 == in.size()) {
    const std::uint32_t v = std::uint8_t(in[i]) << 16;
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += "==";
  } else if (i + 2 == in.size()) {
    const std::uint32_t v = (std::uint8_t(in[i]) << 16) | (std::uint8_t(in[i + 1]) << 8);
    out += kAlphabet[(v >> 18) & 63];
    out += kAlphabet[(v >> 12) & 63];
    out += kAlphabet[(v >> 6) & 63];
    out += '=';
  }
  return out;
}

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

bool printable_ascii(std::string_view s) {
  return std::all_of(s.begin(), s.end(), [](char c) { return c >= 0x20 && c <= 0x7e; });
}

// Request headers that become call metadata. Everything else (HTTP, CORS,
// x-grpc-web, x-user-agent) stays at the HTTP layer; grpc-timeout becomes the
// deadline. The API key too, so that browsers can create and list sessions
// on a server with --api-keys.
constexpr std::string_view kForwardedHeaders[] = {"x-filigree-token", "x-filigree-api-key", "x-session-id"};

}  // namespace

// ------------------------------------------------------------ framing

std::string encode_frame(std::uint8_t flags, std::string_view payload) {
  std::string out;
  out.reserve(kFrameHeader + payload.size());
  const auto n = static_cast<std::uint32_t>(payload.size());
  out += static_cast<char>(flags);
  for (int s : {24, 16, 8, 0}) out += static_cast<char>((n >> s) & 0xff);
  out.append(payload);
  return out;
}

std::string percent_encode(std::string_view message) {
  static constexpr char kHex[] = "0123456789ABCDEF";
  std::string out;
  out.reserve(message.size());
  for (const char ch : message) {
    const auto c = static_cast<unsigned char>(ch);
    if (c >= 0x20 && c <= 0x7e && c != '%') {
      out += ch;
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

std::string encode_trailer_frame(const grpc::Status& status,
                                 const std::multimap<grpc::string_ref, grpc::string_ref>& metadata) {
  std::string lines = "grpc-status:" + std::to_string(static_cast<int>(status.error_code())) + "\r\n";
  if (!status.error_message().empty()) lines += "grpc-message:" + percent_encode(status.error_message()) + "\r\n";
  if (!status.error_details().empty()) lines += "grpc-status-details-bin:" + base64(status.error_details()) + "\r\n";
  for (const auto& [key_ref, value_ref] : metadata) {
    const std::string_view key(key_ref.data(), key_ref.size()), value(value_ref.data(), value_ref.size());
    if (key == "grpc-status" || key == "grpc-message" || key == "grpc-status-details-bin") continue;
    const bool binary = key.size() > 4 && key.substr(key.size() - 4) == "-bin";
    if (!binary && !printable_ascii(value)) continue;
    lines.append(key).append(":").append(binary ? base64(value) : std::string(value)).append("\r\n");
  }
  return encode_frame(kTrailerFrame, lines);
}

grpc::Status parse_request_body(std::string_view body, std::vector<std::string_view>* messages) {
  messages->clear();
  if (body.size() < kFrameHeader)
    return {grpc::StatusCode::INVALID_ARGUMENT,
            "malformed gRPC-Web request: the body must be length-prefixed messages (" + std::to_string(body.size()) +
                " bytes is too short)"};
  while (!body.empty()) {
    if (body.size() < kFrameHeader)
      return {grpc::StatusCode::INVALID_ARGUMENT,
              "malformed gRPC-Web request: " + std::to_string(body.size()) + " bytes after the last message"};
    const auto flags = static_cast<std::uint8_t>(body[0]);
    if (flags == 0x01)
      return {grpc::StatusCode::UNIMPLEMENTED, "compressed gRPC-Web request messages are not supported"};
    if (flags != kDataFrame)
      return {grpc::StatusCode::INVALID_ARGUMENT,
              "malformed gRPC-Web request: frame flag " + std::to_string(flags) + " (expected 0, a data frame)"};
    std::uint64_t n = 0;
    for (int i = 1; i < 5; ++i) n = (n << 8) | static_cast<std::uint8_t>(body[i]);
    if (n > body.size() - kFrameHeader)
      return {grpc::StatusCode::INVALID_ARGUMENT, "malformed gRPC-Web request: a frame announces " + std::to_string(n) +
                                                      " bytes, the body holds " + std::to_string(body.size() - kFrameHeader)};
    messages->push_back(body.substr(kFrameHeader, n));
    body.remove_prefix(kFrameHeader + n);
  }
  return grpc::Status::OK;
}

std::optional<std::chrono::nanoseconds> parse_grpc_timeout(std::string_view value) {
  if (value.size() < 2 || value.size() > 9) return std::nullopt;
  std::int64_t n = 0;
  for (const char c : value.substr(0, value.size() - 1)) {
    if (c < '0' || c > '9') return std::nullopt;
    n = n * 10 + (c - '0');
  }
  using namespace std::chrono;
  // Eight digits of hours overflow int64 nanoseconds (found by fuzz_grpc_web):
  // a timeout that long is as good as none.
  const auto saturated = [n](auto unit) -> nanoseconds {
    using Unit = decltype(unit);
    if (n > duration_cast<Unit>(nanoseconds::max()).count()) return nanoseconds::max();
    return duration_cast<nanoseconds>(Unit(n));
  };
  switch (value.back()) {
    case 'H': return saturated(hours{});
    case 'M': return saturated(minutes{});
    case 'S': return saturated(seconds{});
    case 'm': return saturated(milliseconds{});
    case 'u': return saturated(microseconds{});
    case 'n': return nanoseconds(n);
    default: return std::nullopt;
  }
}

bool is_grpc_web_binary(std::string_view content_type) {
  const std::string type = lower(content_type.substr(0, content_type.find(';')));
  const auto end = type.find_last_not_of(" \t");
  const std::string_view t = std::string_view(type).substr(0, end == std::string::npos ? 0 : end + 1);
  return t == "application/grpc-web" || t == "application/grpc-web+proto";
}

// ------------------------------------------------------------ calls

struct GrpcWebBridge::Inflight {
  std::mutex mutex;
  std::condition_variable idle;
  std::uint64_t next_id = 0;
  std::unordered_map<std::uint64_t, std::weak_ptr<GrpcWebCall>> calls;
};

namespace {

// One upstream call, unary or server streaming alike: a bidi reactor on the
// generic stub writes the one request with the half-close, then reads until
// the end. A hold keeps OnDone back until the last read is done, so that
// every message is delivered before the trailer.
class BridgeCall final : public grpc::ClientBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>, public GrpcWebCall {
 public:
  BridgeCall(std::shared_ptr<GrpcWebBridge::Inflight> inflight, std::string method, GrpcWebEvents events)
      : inflight_(std::move(inflight)), method_(std::move(method)), events_(std::move(events)) {}

  grpc::ClientContext& context() { return context_; }

  // Writes `messages` (views into `body`, which the call keeps until it is
  // done: they are written from it in place), half-closes, and reads.
  static void start(const std::shared_ptr<BridgeCall>& self, grpc::GenericStub& stub,
                    std::shared_ptr<const std::string> body, const std::vector<std::string_view>& messages) {
    self->self_ = self;  // released in OnDone
    {
      std::lock_guard lock(self->inflight_->mutex);
      self->id_ = self->inflight_->next_id++;
      self->inflight_->calls.emplace(self->id_, self);
    }
    self->body_ = std::move(body);
    for (const std::string_view m : messages) {
      grpc::Slice slice(m.data(), m.size(), grpc::Slice::STATIC_SLICE);  // body_ outlives the call
      self->requests_.emplace_back(&slice, 1);
    }
    stub.PrepareBidiStreamingCall(&self->context_, self->method_, grpc::StubOptions(), self.get());
    self->AddHold();
    self->write_next();
    self->reading_ = true;
    self->StartRead(&self->response_);
    self->StartCall();
  }

  // The next request message; the last goes with the half-close.
  void write_next() {
    const std::size_t i = written_++;
    if (i + 1 == requests_.size()) return StartWriteLast(&requests_[i], grpc::WriteOptions());
    StartWrite(&requests_[i]);
  }
  void OnWriteDone(bool ok) override {
    if (ok && written_ < requests_.size()) write_next();  // not ok: the call ends, OnDone says why
  }

  void read_more() override {
    {
      std::lock_guard lock(mutex_);
      if (reading_ || read_finished_) return;
      reading_ = true;
    }
    StartRead(&response_);
  }

  void cancel() override {
    context_.TryCancel();
    {
      std::lock_guard lock(mutex_);
      cancelled_ = true;
      // Keep reading (and dropping) so that the hold is released.
      if (reading_ || read_finished_) return;
      reading_ = true;
    }
    StartRead(&response_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      {
        std::lock_guard lock(mutex_);
        reading_ = false;
        read_finished_ = true;
      }
      RemoveHold();
      return;
    }
    std::string frame = frame_of(response_);
    response_.Clear();
    bool drop;
    {
      std::lock_guard lock(mutex_);
      drop = cancelled_;
      reading_ = drop;
    }
    if (drop) {
      StartRead(&response_);
      return;
    }
    events_.on_data(std::move(frame));
  }

  void OnDone(const grpc::Status& status) override {
    std::shared_ptr<BridgeCall> keep = std::move(self_);
    {
      std::lock_guard lock(mutex_);
      read_finished_ = true;
    }
    {
      // The callbacks (and what they hold) are gone before the call stops
      // counting as in flight: wait_idle() then means nothing refers to the HTTP side.
      GrpcWebEvents events = std::move(events_);
      events_ = {};
      events.on_end(encode_trailer_frame(status, context_.GetServerTrailingMetadata()));
    }
    // When nothing else holds this call, it is destroyed here, its
    // ClientContext with it, before it stops counting as in flight: a server
    // shutting down after wait_idle() must not race a gRPC thread still
    // tearing the call down (it aborted in gRPC's ref counting, ~1 run in 10
    // of the HTTPS reload test on two busy cores). When the HTTP side still
    // holds it, it goes on an io thread (joined by HttpServer::shutdown) or
    // with the io_context's handlers (destroyed after that): ordered before
    // the server is gone either way. Only locals after this.
    const std::shared_ptr<GrpcWebBridge::Inflight> inflight = inflight_;
    const std::uint64_t id = id_;
    keep.reset();
    std::lock_guard lock(inflight->mutex);
    inflight->calls.erase(id);
    if (inflight->calls.empty()) inflight->idle.notify_all();
  }

 private:
  static std::string frame_of(const grpc::ByteBuffer& buffer) {
    std::vector<grpc::Slice> slices;
    (void)buffer.Dump(&slices);
    std::string out;
    out.reserve(kFrameHeader + buffer.Length());
    const auto n = static_cast<std::uint32_t>(buffer.Length());
    out += static_cast<char>(kDataFrame);
    for (int s : {24, 16, 8, 0}) out += static_cast<char>((n >> s) & 0xff);
    for (const grpc::Slice& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
    return out;
  }

  const std::shared_ptr<GrpcWebBridge::Inflight> inflight_;
  std::uint64_t id_ = 0;
  const std::string method_;  // outlives the call: gRPC may keep a pointer to it
  GrpcWebEvents events_;
  std::shared_ptr<BridgeCall> self_;
  grpc::ClientContext context_;
  std::shared_ptr<const std::string> body_;   // what requests_ point into
  std::vector<grpc::ByteBuffer> requests_;
  std::size_t written_ = 0;
  grpc::ByteBuffer response_;
  std::mutex mutex_;
  bool reading_ = false, read_finished_ = false, cancelled_ = false;
};

}  // namespace

GrpcWebBridge::GrpcWebBridge(std::shared_ptr<grpc::Channel> channel, const std::vector<std::string>& services,
                             std::function<std::shared_ptr<grpc::Channel>(const std::string&)> route,
                             std::vector<std::string> request_streams)
    : channel_(std::move(channel)), route_(std::move(route)), request_streams_(request_streams.begin(), request_streams.end()),
      inflight_(std::make_shared<Inflight>()) {
  const auto* pool = google::protobuf::DescriptorPool::generated_pool();
  for (const std::string& name : services) {
    const google::protobuf::ServiceDescriptor* service = pool->FindServiceByName(name);
    if (!service) throw std::invalid_argument("gRPC-Web: unknown service " + name);
    for (int i = 0; i < service->method_count(); ++i) {
      const google::protobuf::MethodDescriptor* m = service->method(i);
      const Kind kind = m->client_streaming() ? (m->server_streaming() ? Kind::kBidiStreaming : Kind::kClientStreaming)
                                              : (m->server_streaming() ? Kind::kServerStreaming : Kind::kUnary);
      methods_.emplace("/" + service->full_name() + "/" + m->name(), kind);
    }
  }
}

GrpcWebBridge::~GrpcWebBridge() {
  cancel_all();
  if (!wait_idle(std::chrono::steady_clock::now() + std::chrono::seconds(5)))
    spdlog::warn("event=grpc_web_calls_still_running");
}

std::string GrpcWebBridge::too_large(std::size_t limit) {
  return encode_trailer_frame({grpc::StatusCode::RESOURCE_EXHAUSTED,
                               "the gRPC-Web request body is over the server's limit of " + std::to_string(limit) + " bytes"});
}

GrpcWebBridge::Started GrpcWebBridge::start(const GrpcWebRequest& request, GrpcWebEvents events) {
  Started out;
  const auto refuse = [&out](grpc::StatusCode code, const std::string& message) {
    out.immediate = encode_trailer_frame({code, message});
    return std::move(out);
  };
  const auto it = methods_.find(request.path);
  if (it == methods_.end()) return refuse(grpc::StatusCode::UNIMPLEMENTED, "unknown method " + request.path);
  const bool streams_requests = it->second == Kind::kClientStreaming || it->second == Kind::kBidiStreaming;
  if (streams_requests && !request_streams_.count(request.path))
    return refuse(grpc::StatusCode::UNIMPLEMENTED,
                  request.path.substr(1) + " streams requests, which gRPC-Web cannot carry: browsers send poses with " +
                      "SubmitPose (unary) and receive frames with Watch; an upload (CreateSession) sends its messages " +
                      "in one body");
  if (!is_grpc_web_binary(request.content_type))
    return refuse(grpc::StatusCode::UNIMPLEMENTED,
                  "content type '" + request.content_type + "' is not served: use application/grpc-web+proto");
  const std::shared_ptr<const std::string> body = request.body ? request.body : std::make_shared<const std::string>();
  std::vector<std::string_view> messages;
  if (grpc::Status s = parse_request_body(*body, &messages); !s.ok()) return refuse(s.error_code(), s.error_message());
  if (!streams_requests && messages.size() != 1)
    return refuse(grpc::StatusCode::INVALID_ARGUMENT, "malformed gRPC-Web request: " + request.path.substr(1) +
                                                          " takes exactly one message, the body holds " +
                                                          std::to_string(messages.size()));

  auto call = std::make_shared<BridgeCall>(inflight_, request.path, std::move(events));
  grpc::ClientContext& context = call->context();
  std::shared_ptr<grpc::Channel> channel = channel_;
  for (const auto& [name, value] : request.headers) {
    if (name == "x-session-id" && route_ && !value.empty())
      if (auto routed = route_(value)) channel = std::move(routed);
    if (name == "grpc-timeout") {
      const auto timeout = parse_grpc_timeout(value);
      if (!timeout) return refuse(grpc::StatusCode::INVALID_ARGUMENT, "malformed grpc-timeout header '" + value + "'");
      context.set_deadline(std::chrono::system_clock::now() +
                           std::chrono::duration_cast<std::chrono::system_clock::duration>(*timeout));
      continue;
    }
    if (std::find(std::begin(kForwardedHeaders), std::end(kForwardedHeaders), name) == std::end(kForwardedHeaders)) continue;
    if (!printable_ascii(value)) return refuse(grpc::StatusCode::INVALID_ARGUMENT, "header " + name + " is not printable ASCII");
    context.AddMetadata(name, value);
  }
  grpc::GenericStub stub(channel);
  BridgeCall::start(call, stub, body, messages);
  out.call = std::move(call);
  out.server_streaming = it->second == Kind::kServerStreaming || it->second == Kind::kBidiStreaming;
  return out;
}

void GrpcWebBridge::cancel_all() {
  std::vector<std::shared_ptr<GrpcWebCall>> calls;
  {
    std::lock_guard lock(inflight_->mutex);
    for (const auto& [id, weak] : inflight_->calls)
      if (auto c = weak.lock()) calls.push_back(std::move(c));
  }
  // Outside the lock: cancelling may run a call's OnDone inline.
  for (const auto& c : calls) c->cancel();
}

bool GrpcWebBridge::wait_idle(std::chrono::steady_clock::time_point deadline) {
  std::unique_lock lock(inflight_->mutex);
  return inflight_->idle.wait_until(lock, deadline, [&] { return inflight_->calls.empty(); });
}

}  // namespace filigree::server::http
