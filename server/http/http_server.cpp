#include "server/http/http_server.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <limits>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <thread>
#include <type_traits>
#include <unordered_map>

#include <boost/asio/dispatch.hpp>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ssl/context.hpp>
#include <boost/asio/ssl/stream_base.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/strand.hpp>
#include <boost/asio/write.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl/ssl_stream.hpp>
#include <spdlog/spdlog.h>

#include "server/descriptor_headroom.h"
#include "server/http/grpc_web_bridge.h"
#include "server/http/log_redaction.h"
#include "server/http/static_files.h"

namespace filigree::server::http {
namespace {

namespace beast = boost::beast;
namespace bhttp = boost::beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;

// The timeouts and limits clients see are HttpOptions'; these are internal.
constexpr auto kLingerTimeout = std::chrono::seconds(2);  // after our FIN, for the client's
constexpr std::size_t kFirstReadBytes = 4096;  // the read that ends an idle wait
// A refused connection's warning at most this often: under a flood, one line
// says it (with the count), not one per connection.
constexpr auto kRefusalLogInterval = std::chrono::seconds(10);

std::string_view sv(beast::string_view s) { return {s.data(), s.size()}; }

std::string lower(std::string_view s) {
  std::string out(s);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return out;
}

// The request headers a cross-origin page may send (the preflight's answer).
constexpr char kAllowedHeaders[] =
    "content-type, x-grpc-web, x-user-agent, grpc-timeout, x-filigree-token, x-filigree-api-key, x-session-id";

// What Access-Control-Allow-Origin says to a request from `origin` (its
// Origin header, empty if none): nothing unless the origin is configured.
std::optional<std::string> allowed_origin(const std::vector<std::string>& allowed, const std::string& origin) {
  if (origin.empty() || allowed.empty()) return std::nullopt;
  for (const std::string& a : allowed) {
    if (a == "*") return std::string("*");
    if (a == origin) return origin;
  }
  return std::nullopt;
}

// `allowed`: allowed_origin()'s answer; `varies`: the answer depends on the
// request's Origin (a cache must keep one per origin).
template <class Body>
void set_cors(bhttp::response<Body>& res, const std::optional<std::string>& allowed, bool varies) {
  if (varies) res.set(bhttp::field::vary, "Origin");
  if (!allowed) return;
  res.set(bhttp::field::access_control_allow_origin, *allowed);
  res.set(bhttp::field::access_control_expose_headers, "grpc-status, grpc-message, grpc-status-details-bin");
}

template <class Body>
void set_security_headers(bhttp::response<Body>& res, bool https) {
  // The viewer's address carries a token: no Referer may take it to another site.
  res.set("referrer-policy", "no-referrer");
  res.set("x-content-type-options", "nosniff");
  // Browsers that once reached this host over HTTPS never try plaintext for a year.
  if (https) res.set("strict-transport-security", "max-age=31536000");
}

// Origins as browsers send them: "*", or scheme://host[:port] and nothing
// after. Throws std::runtime_error for any other (one that could never match).
void check_origins(const std::vector<std::string>& origins) {
  for (const std::string& o : origins) {
    if (o == "*") continue;
    const auto scheme = o.find("://");
    const bool ok = (o.rfind("http://", 0) == 0 || o.rfind("https://", 0) == 0) && scheme != std::string::npos &&
                    o.size() > scheme + 3 && o.find('/', scheme + 3) == std::string::npos &&
                    o.find_first_of("?#* \t") == std::string::npos;
    if (!ok)
      throw std::runtime_error("--http-cors-origin '" + o.substr(0, 200) +
                               "' is not an origin: give scheme://host[:port] (no path, no trailing slash), or *");
  }
}

template <class Body>
void set_grpc_web(bhttp::response<Body>& res) {
  res.set(bhttp::field::content_type, beast::string_view(kGrpcWebContentType.data(), kGrpcWebContentType.size()));
  res.set(bhttp::field::cache_control, "no-store");
}

}  // namespace

// What the server needs of a connection, whatever its transport.
class ConnectionBase {
 public:
  virtual ~ConnectionBase() = default;
  virtual void start() = 0;
  virtual void stop() = 0;
  virtual void force_close() = 0;
};

struct HttpServer::Impl {
  Impl(HttpOptions o, std::shared_ptr<grpc::Channel> channel)
      : options(std::move(o)), files(options.web_root),
        bridge(std::make_shared<GrpcWebBridge>(std::move(channel), options.grpc_web_services, options.route,
                                               options.upload_paths)),
        tls(options.tls.enabled() ? std::make_unique<HttpsContextSource>(options.tls) : nullptr),
        acceptor(net::make_strand(ioc)), accept_retry(acceptor.get_executor()) {}

  void accept();
  void refuse(tcp::socket& socket);
  void remove(std::uint64_t id) {
    std::lock_guard lock(mutex);
    connections.erase(id);
    if (connections.empty()) all_closed.notify_all();
  }
  std::vector<std::shared_ptr<ConnectionBase>> live_connections();

  HttpOptions options;
  StaticFiles files;
  std::shared_ptr<GrpcWebBridge> bridge;
  std::atomic<unsigned> uploads{0};         // upload bodies being read or running (options.upload_paths)
  std::unique_ptr<HttpsContextSource> tls;  // null: plaintext
  std::string address;

  // Declared before the io_context: handlers it destroys unregister here.
  std::mutex mutex;
  std::condition_variable all_closed;
  std::uint64_t next_connection = 0;
  std::unordered_map<std::uint64_t, std::weak_ptr<ConnectionBase>> connections;
  bool shut_down = false;
  // Over max_connections (the acceptor's strand only).
  std::uint64_t refused_since_log = 0;
  std::chrono::steady_clock::time_point last_refusal_log{};

  net::io_context ioc;
  std::optional<net::executor_work_guard<net::io_context::executor_type>> work;
  tcp::acceptor acceptor;
  net::steady_timer accept_retry;
  std::vector<std::thread> threads;
};

// One HTTP/1.1 connection on its own strand. Requests are served one after
// the other (keep-alive). A gRPC-Web call's events come from gRPC threads and
// are posted to the strand; a server-streaming response is chunked, one
// chunk per frame, and the connection closes when it ends.
//
// Stream: beast::tcp_stream (HTTP) or beast::ssl_stream over one (HTTPS):
// the same code, TLS only adds the handshake and close_notify. Timeouts are
// those of the TCP stream underneath.
template <class Stream>
class Connection final : public ConnectionBase, public std::enable_shared_from_this<Connection<Stream>> {
  static constexpr bool kTls = !std::is_same_v<Stream, beast::tcp_stream>;

 public:
  // `tls`: the context of this connection's whole life (a reload gives later
  // connections another one); null for plaintext.
  Connection(tcp::socket&& socket, std::shared_ptr<net::ssl::context> tls, HttpServer::Impl& server, std::uint64_t id)
      : tls_(std::move(tls)), stream_(open(std::move(socket), tls_.get())), server_(server), id_(id),
        linger_timer_(stream_.get_executor()) {}

  ~Connection() override {
    if (call_) call_->cancel();
    server_.remove(id_);
  }

  void start() override {
    net::dispatch(stream_.get_executor(), [self = this->shared_from_this()] {
      if constexpr (kTls)
        self->handshake();
      else
        self->read_request();
    });
  }

  // Shutdown: close now if waiting for a request, else after the response in progress.
  void stop() override {
    net::post(stream_.get_executor(), [self = this->shared_from_this()] {
      self->stopping_ = true;
      if (self->idle_) self->close();
    });
  }

  void force_close() override {
    net::post(stream_.get_executor(), [self = this->shared_from_this()] { self->close(); });
  }

 private:
  static Stream open(tcp::socket&& socket, net::ssl::context* tls) {
    if constexpr (kTls)
      return Stream(std::move(socket), *tls);
    else
      return Stream(std::move(socket));
  }

  beast::tcp_stream& lowest() { return beast::get_lowest_layer(stream_); }

  // HTTPS: the TLS handshake comes before the first request. A client that
  // fails it (a plaintext request, an untrusted or missing client
  // certificate) is closed: a plaintext client could not read an HTTP error
  // sent back inside TLS anyway, and a wrong-protocol answer would be worse.
  void handshake() {
    idle_ = true;  // shutdown closes a connection still in its handshake
    lowest().expires_after(server_.options.handshake_timeout);
    stream_.async_handshake(net::ssl::stream_base::server, [self = this->shared_from_this()](beast::error_code ec) {
      if (ec) {
        // Debug only: scanners and plaintext clients would fill the log.
        spdlog::debug("event=https_handshake_failed error=\"{}\"", ec.message());
        return self->close();
      }
      self->read_request();
    });
  }

  // ---------------------------------------------------------------- reading

  // Two phases, two deadlines: idle_timeout for the request's first byte,
  // then header_timeout for the rest of its header. One deadline for both
  // would have to be long for idle browsers, and so long for slowloris too.
  void read_request() {
    if (closed_) return;
    if (stopping_) return close();
    idle_ = true;
    upload_slot_.reset();
    upload_ = false;
    parser_.emplace();
    // The larger limit until the header says which request this is (on_header).
    parser_->body_limit(std::max(server_.options.max_request_bytes, server_.options.max_upload_bytes));
    parser_->header_limit(static_cast<std::uint32_t>(
        std::min<std::size_t>(server_.options.max_header_bytes, std::numeric_limits<std::uint32_t>::max())));
    if (buffer_.size() > 0) return read_header();  // pipelined: the next request has begun already
    lowest().expires_after(server_.options.idle_timeout);
    stream_.async_read_some(buffer_.prepare(kFirstReadBytes),
                            [self = this->shared_from_this()](beast::error_code ec, std::size_t n) {
                              if (ec) return self->close();  // the client closed, or stayed idle too long
                              self->buffer_.commit(n);
                              self->read_header();
                            });
  }

  void read_header() {
    lowest().expires_after(server_.options.header_timeout);
    bhttp::async_read_header(stream_, buffer_, *parser_,
                             [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->on_header(ec); });
  }

  void on_header(beast::error_code ec) {
    if (ec == bhttp::error::header_limit) return refuse_header_too_large();
    // body_limit here: the header is parsed, its Content-Length is over the limit.
    const bool too_large = ec == bhttp::error::body_limit;
    if (ec && !too_large) {
      // Debug only: a flood of slow clients would fill the log.
      if (ec == beast::error::timeout) spdlog::debug("event=http_timeout phase=header");
      return close();  // the client closed, timed out, or sent garbage
    }
    idle_ = false;
    const auto& req = parser_->get();
    version_ = req.version();
    keep_alive_ = req.keep_alive();
    const unsigned max_requests = server_.options.max_requests_per_connection;
    if (max_requests != 0 && ++requests_ >= max_requests) keep_alive_ = false;
    head_ = req.method() == bhttp::verb::head;
    // Redacted: the viewer's address carries the session's token.
    request_line_ = std::string(sv(req.method_string())) + " " + redacted_target(sv(req.target()));
    origin_ = std::string(sv(req[bhttp::field::origin]).substr(0, 1024));
    const std::string_view target = sv(req.target());
    const auto& uploads = server_.options.upload_paths;
    upload_ = req.method() == bhttp::verb::post &&
              std::find(uploads.begin(), uploads.end(), target.substr(0, target.find('?'))) != uploads.end();
    if (!too_large && !upload_) {
      // Not an upload: the ordinary limit, for a body announced or chunked.
      const auto announced = parser_->content_length();
      if (announced && *announced > server_.options.max_request_bytes) return refuse_too_large();
      parser_->body_limit(server_.options.max_request_bytes);
    }
    if (too_large) return refuse_too_large();
    if (upload_ && !take_upload_slot()) return refuse_busy_uploads();
    if (lower(sv(req[bhttp::field::expect])) == "100-continue") {
      auto res = std::make_shared<bhttp::response<bhttp::empty_body>>(bhttp::status::continue_, version_);
      lowest().expires_after(server_.options.write_timeout);
      return bhttp::async_write(stream_, *res, [self = this->shared_from_this(), res](beast::error_code ec, std::size_t) {
        if (ec) return self->close();
        self->read_body();
      });
    }
    read_body();
  }

  void read_body() {
    lowest().expires_after(upload_ ? server_.options.upload_timeout : server_.options.body_timeout);
    bhttp::async_read(stream_, buffer_, *parser_,
                      [self = this->shared_from_this()](beast::error_code ec, std::size_t) { self->on_request(ec); });
  }

  void on_request(beast::error_code ec) {
    if (ec == bhttp::error::body_limit) return refuse_too_large();
    if (ec) {
      if (ec == beast::error::timeout) spdlog::debug("event=http_timeout phase=body request=\"{}\"", request_line_);
      return close();
    }
    handle(parser_->release());
  }

  // ---------------------------------------------------------------- routing

  void handle(bhttp::request<bhttp::string_body> req) {
    switch (req.method()) {
      case bhttp::verb::options: return send_preflight();
      case bhttp::verb::post: return handle_grpc_web(std::move(req));
      case bhttp::verb::get:
      case bhttp::verb::head: return serve_file(req);
      default: {
        auto res = text(bhttp::status::method_not_allowed, "method not allowed\n");
        res.set(bhttp::field::allow, "GET, HEAD, POST, OPTIONS");
        return send(std::move(res));
      }
    }
  }

  // A browser asks before a cross-origin call. Only configured origins get
  // the Access-Control-Allow-* answer; another origin gets a 403 (its call
  // would be refused by the browser anyway: this says why, to a person
  // reading the network log). Without an Origin it is no preflight: 204.
  void send_preflight() {
    if (!origin_.empty() && !allowed_origin(server_.options.cors_origins, origin_))
      return send(text(bhttp::status::forbidden,
                       "cross-origin calls from this origin are not allowed here (filigree-server --http-cors-origin)\n"));
    bhttp::response<bhttp::empty_body> res{bhttp::status::no_content, version_};
    res.set(bhttp::field::allow, "GET, HEAD, POST, OPTIONS");
    if (!origin_.empty()) {
      res.set(bhttp::field::access_control_allow_methods, "POST, GET, OPTIONS");
      res.set(bhttp::field::access_control_allow_headers, kAllowedHeaders);
      res.set(bhttp::field::access_control_max_age, "86400");
    }
    send(std::move(res));
  }

  template <class Body>
  void set_response_headers(bhttp::response<Body>& res) {
    res.set(bhttp::field::server, "filigree-server");
    const auto& allowed = server_.options.cors_origins;
    const bool varies = !allowed.empty() && std::find(allowed.begin(), allowed.end(), "*") == allowed.end();
    set_cors(res, allowed_origin(allowed, origin_), varies);
    set_security_headers(res, kTls);
  }

  void serve_file(const bhttp::request<bhttp::string_body>& req) {
    const std::string_view target = sv(req.target());
    if (target.substr(0, target.find('?')) == "/server.json" && !server_.options.server_json.empty()) {
      bhttp::response<bhttp::string_body> res{bhttp::status::ok, version_};
      res.set(bhttp::field::content_type, "application/json");
      res.set(bhttp::field::cache_control, "no-cache");
      if (req.method() != bhttp::verb::head) res.body() = server_.options.server_json;
      res.content_length(server_.options.server_json.size());
      return send(std::move(res));
    }
    const StaticFiles::Result found = server_.files.resolve(target);
    if (found.status != 200) return send(text(static_cast<bhttp::status>(found.status), found.message));
    beast::error_code ec;
    bhttp::file_body::value_type body;
    body.open(found.file.c_str(), beast::file_mode::scan, ec);
    if (ec) return send(text(bhttp::status::not_found, "not found\n"));
    const std::uint64_t size = body.size();
    const auto headers = [&](auto& res) {
      res.set(bhttp::field::content_type, found.content_type);
      res.set(bhttp::field::cache_control, "no-cache");
      res.content_length(size);
    };
    if (req.method() == bhttp::verb::head) {
      bhttp::response<bhttp::empty_body> res{bhttp::status::ok, version_};
      headers(res);
      return send(std::move(res));
    }
    bhttp::response<bhttp::file_body> res{std::piecewise_construct, std::make_tuple(std::move(body)),
                                          std::make_tuple(bhttp::status::ok, version_)};
    headers(res);
    send(std::move(res));
  }

  // ---------------------------------------------------------------- gRPC-Web

  void handle_grpc_web(bhttp::request<bhttp::string_body> req) {
    GrpcWebRequest request;
    request.content_type = std::string(sv(req[bhttp::field::content_type]));
    if (!is_grpc_web_binary(request.content_type))
      return send(text(bhttp::status::unsupported_media_type,
                       "filigree-server answers POST with gRPC-Web only: content type application/grpc-web+proto "
                       "(application/grpc-web-text is not served)\n"));
    const std::string_view target = sv(req.target());
    request.path = std::string(target.substr(0, target.find('?')));
    request.body = std::make_shared<const std::string>(std::move(req.body()));
    for (const auto& field : req) request.headers.emplace_back(lower(sv(field.name_string())), std::string(sv(field.value())));

    const auto self = this->shared_from_this();
    const auto executor = stream_.get_executor();
    GrpcWebEvents events{
        [self, executor](std::string frame) {
          net::post(executor, [self, frame = std::move(frame)]() mutable { self->on_call_data(std::move(frame)); });
        },
        [self, executor](std::string frame) {
          net::post(executor, [self, frame = std::move(frame)]() mutable { self->on_call_end(std::move(frame)); });
        }};
    GrpcWebBridge::Started started = server_.bridge->start(request, std::move(events));
    if (!started.call) return send_grpc_web_body(std::move(started.immediate));
    call_ = std::move(started.call);
    streaming_ = started.server_streaming;
    if (streaming_) begin_stream();
    // Unary: the response is written when on_call_end arrives.
  }

  void on_call_data(std::string frame) {
    if (closed_ || !call_) return;
    if (!streaming_) {
      unary_body_ += frame;
      return call_->read_more();
    }
    out_.push_back({std::move(frame), /*data=*/true});
    pump();
  }

  void on_call_end(std::string trailer) {
    call_.reset();
    if (closed_) return;
    if (!streaming_) {
      unary_body_ += trailer;
      std::string body = std::move(unary_body_);
      unary_body_.clear();
      return send_grpc_web_body(std::move(body));
    }
    out_.push_back({std::move(trailer), /*data=*/false});
    pump();
  }

  void send_grpc_web_body(std::string body) {
    bhttp::response<bhttp::string_body> res{bhttp::status::ok, version_};
    set_grpc_web(res);
    res.body() = std::move(body);
    res.prepare_payload();
    send(std::move(res));
  }

  // One of the options.max_concurrent_uploads places, held until the next
  // request begins or the connection goes.
  bool take_upload_slot() {
    unsigned now = server_.uploads.load();
    do {
      if (now >= server_.options.max_concurrent_uploads) return false;
    } while (!server_.uploads.compare_exchange_weak(now, now + 1));
    upload_slot_ = std::shared_ptr<void>(nullptr, [&uploads = server_.uploads](void*) { --uploads; });
    return true;
  }

  void refuse_busy_uploads() {
    keep_alive_ = false;  // the body is never read
    send_grpc_web_body(encode_trailer_frame(
        {grpc::StatusCode::RESOURCE_EXHAUSTED, "the server reads " + std::to_string(server_.options.max_concurrent_uploads) +
                                                   " browser uploads at once; try again in a moment"}));
  }

  void refuse_too_large() {
    keep_alive_ = false;  // the rest of the body is never read
    const auto& req = parser_->get();
    const std::size_t limit = upload_ ? server_.options.max_upload_bytes : server_.options.max_request_bytes;
    if (req.method() == bhttp::verb::post && is_grpc_web_binary(sv(req[bhttp::field::content_type])))
      return send_grpc_web_body(GrpcWebBridge::too_large(limit));
    send(text(bhttp::status::payload_too_large, "request body over the limit of " + std::to_string(limit) + " bytes\n"));
  }

  // The header is not parsed: what it asked is unknown, so a plain answer
  // in HTTP/1.1, and close (the rest of the header is never read).
  void refuse_header_too_large() {
    idle_ = false;
    version_ = 11;
    keep_alive_ = false;
    head_ = false;
    request_line_ = "(header over the limit)";
    origin_.clear();
    send(text(bhttp::status::request_header_fields_too_large,
              "request header over the limit of " + std::to_string(server_.options.max_header_bytes) + " bytes\n"));
  }

  // A server-streaming response: the header now, then a chunk per frame as
  // it arrives (flushed at once), the trailer frame, the last chunk, close.
  void begin_stream() {
    chunked_ = version_ >= 11;
    auto head = std::make_shared<bhttp::response<bhttp::empty_body>>(bhttp::status::ok, version_);
    set_response_headers(*head);
    set_grpc_web(*head);
    head->set("x-accel-buffering", "no");  // a proxy in front must not buffer the stream
    head->keep_alive(false);
    if (chunked_) head->chunked(true);
    auto serializer = std::make_shared<bhttp::response_serializer<bhttp::empty_body>>(*head);
    writing_ = true;
    lowest().expires_after(server_.options.write_timeout);
    bhttp::async_write_header(stream_, *serializer,
                              [self = this->shared_from_this(), head, serializer](beast::error_code ec, std::size_t) {
                                self->writing_ = false;
                                if (ec) return self->close();
                                spdlog::debug("event=http_request request=\"{}\" status=200 streaming=true", self->request_line_);
                                // Notice a browser that goes away while nothing is being written.
                                self->start_discard_read();
                                self->pump();
                              });
  }

  void pump() {
    if (writing_ || closed_ || out_.empty()) return;
    Out next = std::move(out_.front());
    out_.pop_front();
    wire_.clear();
    if (chunked_) {
      char size[20];
      std::snprintf(size, sizeof size, "%zx\r\n", next.bytes.size());
      wire_.append(size).append(next.bytes).append("\r\n");
      if (!next.data) wire_.append("0\r\n\r\n");  // the trailer frame is the last chunk
    } else {
      wire_ = std::move(next.bytes);
    }
    writing_ = true;
    lowest().expires_after(server_.options.write_timeout);
    net::async_write(stream_, net::buffer(wire_),
                     [self = this->shared_from_this(), data = next.data](beast::error_code ec, std::size_t) {
                       self->writing_ = false;
                       if (ec) return self->close();  // also cancels the upstream call
                       if (!data) return self->linger();
                       if (self->call_) self->call_->read_more();
                       self->pump();
                     });
  }

  // ---------------------------------------------------------------- writing, closing

  static bhttp::response<bhttp::string_body> text(bhttp::status status, std::string body) {
    bhttp::response<bhttp::string_body> res{status, 11};
    res.set(bhttp::field::content_type, "text/plain; charset=utf-8");
    res.body() = std::move(body);
    return res;
  }

  template <class Body>
  void send(bhttp::response<Body>&& res) {
    res.version(version_);
    set_response_headers(res);
    res.keep_alive(keep_alive_ && !stopping_);
    if constexpr (std::is_same_v<Body, bhttp::string_body>) {
      res.prepare_payload();
      if (head_) res.body().clear();  // the Content-Length of what GET would send, no body
    }
    spdlog::debug("event=http_request request=\"{}\" status={}", request_line_, res.result_int());
    auto sp = std::make_shared<bhttp::response<Body>>(std::move(res));
    lowest().expires_after(server_.options.write_timeout);
    bhttp::async_write(stream_, *sp, [self = this->shared_from_this(), sp](beast::error_code ec, std::size_t) {
      if (ec) return self->close();
      if (!sp->keep_alive()) return self->linger();
      self->read_request();
    });
  }

  // Reads and drops whatever the client sends; its end (EOF, reset) closes
  // the connection — while streaming, that cancels the upstream call.
  void start_discard_read() {
    if (discard_reading_ || closed_) return;
    discard_reading_ = true;
    // Beneath TLS: bytes are only counted out, and the TLS stream may be
    // writing a response meanwhile.
    lowest().socket().async_read_some(net::buffer(discard_),
                                     [self = this->shared_from_this()](beast::error_code ec, std::size_t) {
                                       self->discard_reading_ = false;
                                       if (self->closed_) return;
                                       if (ec) return self->close();
                                       self->start_discard_read();
                                     });
  }

  // Graceful close: our FIN first, then wait (bounded) for the client's, so
  // that unread request bytes cannot turn our close into a reset that loses
  // the response.
  void linger() {
    if (closed_) return;
    linger_timer_.expires_after(kLingerTimeout);
    linger_timer_.async_wait([self = this->shared_from_this()](beast::error_code ec) {
      if (!ec) self->close();
    });
    if constexpr (kTls) {
      // HTTPS: close_notify before the FIN, so that the client sees a clean
      // end rather than a possible truncation; the TLS shutdown waits
      // (bounded by the timer) for the client's. Not after a stream: a read
      // beneath TLS is already in progress (start_discard_read), and the
      // chunked body has said where it ends.
      if (!discard_reading_)
        return stream_.async_shutdown([self = this->shared_from_this()](beast::error_code) { self->linger_tcp(); });
    }
    linger_tcp();
  }

  void linger_tcp() {
    if (closed_) return;
    beast::error_code ec;
    lowest().socket().shutdown(tcp::socket::shutdown_send, ec);
    if (ec) return close();
    start_discard_read();
  }

  void close() {
    if (closed_) return;
    closed_ = true;
    if (call_) call_->cancel();  // its on_call_end still comes, and is dropped
    linger_timer_.cancel();
    beast::error_code ec;
    lowest().socket().shutdown(tcp::socket::shutdown_both, ec);
    lowest().close();
  }

  struct Out {
    std::string bytes;
    bool data;  // a data frame (else the trailer frame)
  };

  std::shared_ptr<net::ssl::context> tls_;  // before stream_, which refers to it
  Stream stream_;
  HttpServer::Impl& server_;
  const std::uint64_t id_;
  net::steady_timer linger_timer_;
  beast::flat_buffer buffer_;
  std::optional<bhttp::request_parser<bhttp::string_body>> parser_;
  unsigned version_ = 11;
  std::string request_line_;  // for log lines: secrets redacted
  std::string origin_;        // the request's Origin header; empty: none
  bool keep_alive_ = true, head_ = false, idle_ = false, stopping_ = false, closed_ = false;
  unsigned requests_ = 0;  // begun on this connection
  bool upload_ = false;    // this request's body is an upload (options.upload_paths)
  std::shared_ptr<void> upload_slot_;
  // gRPC-Web
  std::shared_ptr<GrpcWebCall> call_;
  std::string unary_body_;
  bool streaming_ = false, chunked_ = true, writing_ = false, discard_reading_ = false;
  std::deque<Out> out_;
  std::string wire_;
  std::array<char, 4096> discard_{};
};

// Descriptors left free when a browser connection is accepted: more than
// the gRPC port's relays keep, so the browser port never takes the last ones.
constexpr std::size_t kDescriptorHeadroom = 32;

void HttpServer::Impl::accept() {
  acceptor.async_accept(net::make_strand(ioc), [this](beast::error_code ec, tcp::socket socket) {
    if (ec == net::error::operation_aborted || !acceptor.is_open()) return;
    if (ec) {
      // Out of descriptors, most likely: try again a little later rather than spin.
      spdlog::warn("event=http_accept_failed error=\"{}\"", ec.message());
      accept_retry.expires_after(std::chrono::milliseconds(100));
      accept_retry.async_wait([this](beast::error_code e) {
        if (!e) accept();
      });
      return;
    }
    beast::error_code ignored;
    socket.set_option(tcp::no_delay(true), ignored);  // frames go out as they come
    // Outside the lock: it may re-read the certificate files.
    std::shared_ptr<net::ssl::context> context = tls ? tls->current() : nullptr;
    std::shared_ptr<ConnectionBase> connection;
    bool full = false;
    {
      std::lock_guard lock(mutex);
      // A headroom of descriptors stays free for the gRPC port (descriptor_headroom.h).
      full = (options.max_connections != 0 && connections.size() >= options.max_connections) ||
             !descriptors_free(kDescriptorHeadroom);
      if (!shut_down && !full) {
        const std::uint64_t id = next_connection++;
        using TlsConnection = Connection<beast::ssl_stream<beast::tcp_stream>>;
        if (context)
          connection = std::make_shared<TlsConnection>(std::move(socket), std::move(context), *this, id);
        else
          connection = std::make_shared<Connection<beast::tcp_stream>>(std::move(socket), nullptr, *this, id);
        connections.emplace(id, connection);
      }
    }
    if (connection) connection->start();
    if (full) refuse(socket);
    accept();
  });
}

// Over max_connections: answered and closed on the acceptor's strand, never
// read from, so that a flood costs no more than the accept. Plaintext gets a
// 503 written into the fresh socket's (empty) send buffer; should the client
// have sent its request already, the close may reset the connection before
// the 503 is read, which the client sees as a failed connection all the same.
void HttpServer::Impl::refuse(tcp::socket& socket) {
  beast::error_code ec;
  if (!tls) {
    static constexpr std::string_view kBusy =
        "HTTP/1.1 503 Service Unavailable\r\nServer: filigree-server\r\nRetry-After: 1\r\n"
        "Referrer-Policy: no-referrer\r\nX-Content-Type-Options: nosniff\r\n"
        "Content-Type: text/plain; charset=utf-8\r\nContent-Length: 26\r\nConnection: close\r\n\r\n"
        "too many open connections\n";
    socket.non_blocking(true, ec);
    if (!ec) socket.write_some(net::buffer(kBusy.data(), kBusy.size()), ec);
    socket.shutdown(tcp::socket::shutdown_send, ec);
  }
  socket.close(ec);
  ++refused_since_log;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_refusal_log >= kRefusalLogInterval) {
    spdlog::warn("event=http_connection_refused reason=max_connections max_connections={} refused={}",
                 options.max_connections, refused_since_log);
    refused_since_log = 0;
    last_refusal_log = now;
  }
}

std::vector<std::shared_ptr<ConnectionBase>> HttpServer::Impl::live_connections() {
  std::vector<std::shared_ptr<ConnectionBase>> out;
  std::lock_guard lock(mutex);
  for (const auto& [id, weak] : connections)
    if (auto c = weak.lock()) out.push_back(std::move(c));
  return out;
}

HttpServer::HttpServer(HttpOptions options, std::shared_ptr<grpc::Channel> channel)
    : impl_(std::make_unique<Impl>(std::move(options), std::move(channel))) {
  Impl& s = *impl_;
  check_origins(s.options.cors_origins);
  const std::string& listen = s.options.listen;
  const auto colon = listen.rfind(':');
  if (colon == std::string::npos) throw std::runtime_error("--http wants HOST:PORT, got '" + listen + "'");
  const std::string host = listen.substr(0, colon), port = listen.substr(colon + 1);
  std::string bare_host = host;
  if (bare_host.size() >= 2 && bare_host.front() == '[' && bare_host.back() == ']')
    bare_host = bare_host.substr(1, bare_host.size() - 2);

  beast::error_code ec;
  tcp::resolver resolver(s.ioc);
  const auto results =
      resolver.resolve(bare_host, port, tcp::resolver::passive | tcp::resolver::numeric_service, ec);
  if (ec || results.empty()) throw std::runtime_error("cannot resolve HTTP address " + listen + ": " + ec.message());
  const tcp::endpoint endpoint = results.begin()->endpoint();
  s.acceptor.open(endpoint.protocol(), ec);
  if (!ec) s.acceptor.set_option(net::socket_base::reuse_address(true), ec);
  if (!ec) s.acceptor.bind(endpoint, ec);
  if (!ec) s.acceptor.listen(net::socket_base::max_listen_connections, ec);
  if (ec) throw std::runtime_error("cannot listen for HTTP on " + listen + ": " + ec.message());
  s.address = host + ":" + std::to_string(s.acceptor.local_endpoint().port());

  s.accept();
  s.work.emplace(s.ioc.get_executor());
  for (int i = 0; i < std::max(1, s.options.threads); ++i)
    s.threads.emplace_back([&s] {
      for (;;) {
        try {
          s.ioc.run();
          return;
        } catch (const std::exception& e) {
          spdlog::error("event=http_thread_error error=\"{}\"", e.what());
        }
      }
    });
  std::string cors;
  for (const std::string& o : s.options.cors_origins) cors += (cors.empty() ? "" : ",") + o;
  spdlog::info("event=http_listening address={} transport={} web_root=\"{}\" cors_origins=\"{}\"", s.address,
               !s.tls ? "plaintext" : s.options.tls.client_ca.empty() ? "https" : "https-mutual-tls",
               s.files.root() ? s.files.root()->string() : std::string(), cors);
}

HttpServer::~HttpServer() { shutdown(); }

std::string HttpServer::address() const { return impl_ ? impl_->address : std::string(); }

bool HttpServer::https() const { return impl_ && impl_->tls; }

void HttpServer::reload_certificates() {
  if (impl_ && impl_->tls) impl_->tls->reload();
}

void HttpServer::stop_accepting() {
  if (!impl_) return;
  Impl* s = impl_.get();
  net::post(s->acceptor.get_executor(), [s] {
    beast::error_code ec;
    s->acceptor.close(ec);
    s->accept_retry.cancel();
  });
}

void HttpServer::shutdown(std::chrono::milliseconds grace) {
  if (!impl_) return;
  Impl& s = *impl_;
  {
    std::lock_guard lock(s.mutex);
    if (s.shut_down) return;
    s.shut_down = true;
  }
  stop_accepting();
  for (const auto& c : s.live_connections()) c->stop();
  {
    std::unique_lock lock(s.mutex);
    s.all_closed.wait_until(lock, std::chrono::steady_clock::now() + grace, [&] { return s.connections.empty(); });
  }
  for (const auto& c : s.live_connections()) c->force_close();
  s.bridge->cancel_all();
  const bool idle = s.bridge->wait_idle(std::chrono::steady_clock::now() + std::chrono::seconds(5));
  s.work.reset();
  s.ioc.stop();
  for (std::thread& t : s.threads) t.join();
  s.threads.clear();
  if (!idle) {
    // A call that never ended still refers to a connection, and so to this
    // server: leak it rather than free it under the call.
    spdlog::error("event=http_shutdown_incomplete reason=\"gRPC-Web calls still running\"");
    (void)impl_.release();
  }
  spdlog::info("event=http_stopped");
}

}  // namespace filigree::server::http
