// filigree-server's HTTP face, end to end: gRPC-Web (the protocol browsers
// speak through @connectrpc/connect-web or Envoy's grpc_web filter) for the
// same service, CORS, and the web viewer's static files. A small Beast HTTP
// client plays the browser; sessions are uploaded over native gRPC.

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "support/grpc_web_frames.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

namespace beast = boost::beast;
namespace bhttp = boost::beast::http;
namespace net = boost::asio;
using tcp = net::ip::tcp;
using test::Frame;
using test::frame_bytes;
using test::ServerProcess;
using test::take_frame;

using test::file_bytes;

// ------------------------------------------------------------ gRPC-Web wire format

std::string percent_decode(const std::string& s) {
  std::string out;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size()) {
      out += static_cast<char>(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

// "key:value\r\n" lines (keys lower case, values trimmed).
std::map<std::string, std::string> parse_trailer(const std::string& payload) {
  std::map<std::string, std::string> out;
  std::size_t at = 0;
  while (at < payload.size()) {
    std::size_t end = payload.find("\r\n", at);
    if (end == std::string::npos) end = payload.size();
    const std::string line = payload.substr(at, end - at);
    const auto colon = line.find(':');
    if (colon != std::string::npos) {
      std::string value = line.substr(colon + 1);
      value.erase(0, value.find_first_not_of(' '));
      out[line.substr(0, colon)] = value;
    }
    at = end + 2;
  }
  return out;
}

// A gRPC-Web response read whole (unary calls).
struct Reply {
  unsigned http_status = 0;
  bhttp::fields headers;
  std::vector<std::string> messages;
  std::map<std::string, std::string> trailer;
  bool one_trailer_last = false;  // exactly one trailer frame, and it is the last frame

  int grpc_status() const { return trailer.count("grpc-status") ? std::stoi(trailer.at("grpc-status")) : -1; }
  std::string grpc_message() const { return trailer.count("grpc-message") ? percent_decode(trailer.at("grpc-message")) : ""; }
};

// ------------------------------------------------------------ a small HTTP client

// Asynchronous Beast operations run to completion one at a time, so that
// every read and write has a timeout (tcp_stream's) and a test cannot hang.
class HttpClient {
 public:
  explicit HttpClient(const std::string& address) {
    const auto colon = address.rfind(':');
    tcp::resolver resolver(ioc_);
    const auto endpoints = resolver.resolve(address.substr(0, colon), address.substr(colon + 1));
    const beast::error_code ec = run([&](auto handler) { stream_.async_connect(endpoints, handler); });
    if (ec) throw std::runtime_error("connect to " + address + ": " + ec.message());
  }

  // One whole request and response.
  bhttp::response<bhttp::string_body> exchange(const bhttp::request<bhttp::string_body>& req) {
    write(req);
    bhttp::response<bhttp::string_body> res;
    bhttp::response_parser<bhttp::string_body> parser;
    parser.body_limit(64u << 20);
    if (req.method() == bhttp::verb::head) parser.skip(true);
    const beast::error_code ec = run([&](auto handler) { bhttp::async_read(stream_, buffer_, parser, handler); });
    if (ec) throw std::runtime_error("read: " + ec.message());
    return parser.release();
  }

  // Raw bytes out (for requests a well-behaved client would not send).
  void write_raw(const std::string& bytes) {
    const beast::error_code ec = run([&](auto handler) { net::async_write(stream_, net::buffer(bytes), handler); });
    if (ec) throw std::runtime_error("write: " + ec.message());
  }

  void write(const bhttp::request<bhttp::string_body>& req) {
    const beast::error_code ec = run([&](auto handler) { bhttp::async_write(stream_, req, handler); });
    if (ec) throw std::runtime_error("write: " + ec.message());
  }

  // Streaming: the response header, then frames as they come.
  const bhttp::response_parser<bhttp::buffer_body>::value_type& read_stream_header() {
    stream_parser_.emplace();
    stream_parser_->body_limit(boost::none);
    const beast::error_code ec = run([&](auto handler) { bhttp::async_read_header(stream_, buffer_, *stream_parser_, handler); });
    if (ec) throw std::runtime_error("read header: " + ec.message());
    return stream_parser_->get();
  }

  // The next frame of the streamed body; nullopt when the body ended.
  std::optional<Frame> next_frame() {
    for (;;) {
      if (auto f = take_frame(pending_)) return f;
      if (stream_parser_->is_done()) return std::nullopt;
      char chunk[8192];
      stream_parser_->get().body().data = chunk;
      stream_parser_->get().body().size = sizeof chunk;
      beast::error_code ec = run([&](auto handler) { bhttp::async_read_some(stream_, buffer_, *stream_parser_, handler); });
      if (ec == bhttp::error::need_buffer) ec = {};
      if (ec) throw std::runtime_error("read body: " + ec.message());
      pending_.append(chunk, sizeof chunk - stream_parser_->get().body().size);
    }
  }

  void close() {
    beast::error_code ec;
    stream_.socket().shutdown(tcp::socket::shutdown_both, ec);
    stream_.close();
  }

 private:
  template <class Start>
  beast::error_code run(Start start) {
    beast::error_code result;
    stream_.expires_after(std::chrono::seconds(30));
    start([&result](beast::error_code ec, auto&&...) { result = ec; });
    ioc_.restart();
    ioc_.run();
    return result;
  }

  net::io_context ioc_;
  beast::tcp_stream stream_{ioc_};
  beast::flat_buffer buffer_;
  std::optional<bhttp::response_parser<bhttp::buffer_body>> stream_parser_;
  std::string pending_;
};

using Headers = std::vector<std::pair<std::string, std::string>>;

bhttp::request<bhttp::string_body> grpc_web_request(const std::string& method, const std::string& body,
                                                    const Headers& headers) {
  bhttp::request<bhttp::string_body> req{bhttp::verb::post, "/filigree.v1.Filigree/" + method, 11};
  req.set(bhttp::field::host, "localhost");
  req.set(bhttp::field::content_type, "application/grpc-web+proto");
  req.set("x-grpc-web", "1");
  req.set("x-user-agent", "connect-es/2.0.4");
  for (const auto& [k, v] : headers) req.set(k, v);
  req.body() = body;
  req.prepare_payload();
  return req;
}

Reply to_reply(const bhttp::response<bhttp::string_body>& res) {
  Reply r;
  r.http_status = res.result_int();
  r.headers = res.base();
  std::string body = res.body();
  std::vector<Frame> frames;
  while (auto f = take_frame(body)) frames.push_back(*f);
  EXPECT_TRUE(body.empty()) << "bytes after the last whole frame";
  int trailers = 0;
  for (const Frame& f : frames) {
    if (f.trailer()) {
      ++trailers;
      r.trailer = parse_trailer(f.payload);
    } else {
      EXPECT_EQ(f.flags, 0) << "unexpected frame flags";
      r.messages.push_back(f.payload);
    }
  }
  r.one_trailer_last = trailers == 1 && frames.back().trailer();
  return r;
}

// ------------------------------------------------------------ fixture

class GrpcWebTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scratch_ = std::filesystem::path(::testing::TempDir()) /
               ("filigree_web_" + std::to_string(::getpid()) + "_" + ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(scratch_);
    std::filesystem::create_directories(scratch_ / "www" / "assets");
    write(scratch_ / "www" / "index.html", "<!doctype html><title>Filigree</title>");
    write(scratch_ / "www" / "assets" / "app.js", "export const x = 1;\n");
    write(scratch_ / "www" / "assets" / "style.css", "body { margin: 0 }\n");
    write(scratch_ / "www" / "assets" / "draco.wasm", std::string("\0asm\1\0\0\0", 8));
    write(scratch_ / "secret.txt", "outside the web root");
    server_ = std::make_unique<ServerProcess>(FILIGREE_SERVER_BINARY,
                                              std::vector<std::string>{"--web-root", (scratch_ / "www").string(),
                                                                       "--http-cors-origin", "http://localhost:5173"},
                                              /*http=*/true);
    stub_ = v1::Filigree::NewStub(grpc::CreateChannel(server_->address(), grpc::InsecureChannelCredentials()));
  }
  void TearDown() override {
    server_.reset();
    std::filesystem::remove_all(scratch_);
  }

  static void write(const std::filesystem::path& p, const std::string& bytes) {
    std::ofstream(p, std::ios::binary) << bytes;
  }

  // Uploads bunny_small over native gRPC.
  v1::CreateSessionResponse::Created upload() {
    const std::string bytes = file_bytes(test::shipped_path("bunny_small.obj"));
    grpc::ClientContext ctx;
    auto stream = stub_->CreateSession(&ctx);
    v1::CreateSessionRequest begin;
    begin.mutable_begin()->set_format("obj");
    begin.mutable_begin()->set_total_bytes(bytes.size());
    begin.mutable_begin()->mutable_options()->set_base_vertices(150);
    EXPECT_TRUE(stream->Write(begin));
    v1::CreateSessionRequest chunk;
    chunk.set_chunk(bytes);
    EXPECT_TRUE(stream->Write(chunk));
    stream->WritesDone();
    v1::CreateSessionResponse r;
    v1::CreateSessionResponse::Created created;
    while (stream->Read(&r))
      if (r.has_created()) created = r.created();
    const grpc::Status status = stream->Finish();
    EXPECT_TRUE(status.ok()) << status.error_message();
    return created;
  }

  // One unary gRPC-Web call on a new connection.
  Reply call(const std::string& method, const google::protobuf::Message& request, const Headers& headers) {
    HttpClient client(server_->http_address());
    return to_reply(client.exchange(grpc_web_request(method, frame_bytes(0, request.SerializeAsString()), headers)));
  }

  std::uint32_t watchers(const std::string& session) {
    grpc::ClientContext ctx;
    v1::ListSessionsResponse list;
    EXPECT_TRUE(stub_->ListSessions(&ctx, v1::ListSessionsRequest(), &list).ok());
    for (const auto& e : list.sessions())
      if (e.session_id() == session) return e.watchers();
    return 0;
  }

  std::filesystem::path scratch_;
  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
};

Headers auth(const std::string& session, const std::string& token) {
  return {{"x-session-id", session}, {"x-filigree-token", token}};
}

// ------------------------------------------------------------ tests

TEST_F(GrpcWebTest, JoinSessionReturnsTheSessionInfoAndStatusOk) {
  const auto created = upload();
  const std::string id = created.info().session_id();
  v1::JoinSessionRequest req;
  req.set_session_id(id);
  const Reply r = call("JoinSession", req, auth(id, created.viewer_token()));
  EXPECT_EQ(r.http_status, 200u);
  EXPECT_EQ(std::string(r.headers[bhttp::field::content_type]), "application/grpc-web+proto");
  // Same origin (no Origin header, as the viewer served here): no CORS grant is needed, none is sent.
  EXPECT_EQ(std::string(r.headers[bhttp::field::access_control_allow_origin]), "");
  EXPECT_TRUE(r.one_trailer_last);
  EXPECT_EQ(r.grpc_status(), 0) << r.grpc_message();
  ASSERT_EQ(r.messages.size(), 1u);
  v1::SessionInfo info;
  ASSERT_TRUE(info.ParseFromString(r.messages[0]));
  EXPECT_EQ(info.session_id(), id);
  EXPECT_EQ(info.base().original_ids_size(), 150);
  EXPECT_EQ(info.rest().vertex_count(), 1839u);
  // What CreateSession answered, and the caller's role.
  EXPECT_EQ(info.role(), v1::ROLE_VIEWER);
  info.clear_role();
  EXPECT_EQ(info.SerializeAsString(), created.info().SerializeAsString());

  // No token in the request message either: the x-session-id header names the session.
  const Reply state = call("GetState", v1::GetStateRequest(), auth(id, created.viewer_token()));
  EXPECT_EQ(state.grpc_status(), 0) << state.grpc_message();
  ASSERT_EQ(state.messages.size(), 1u);
  v1::SessionState s;
  ASSERT_TRUE(s.ParseFromString(state.messages[0]));
  EXPECT_EQ(s.pose_size(), 3 * 150);
}

TEST_F(GrpcWebTest, ErrorsComeAsTrailerStatusCodes) {
  const auto created = upload();
  const std::string id = created.info().session_id();
  v1::JoinSessionRequest req;
  req.set_session_id(id);

  const Reply no_token = call("JoinSession", req, {{"x-session-id", id}});
  EXPECT_EQ(no_token.http_status, 200u);
  EXPECT_TRUE(no_token.one_trailer_last);
  EXPECT_TRUE(no_token.messages.empty());
  EXPECT_EQ(no_token.grpc_status(), 16);  // UNAUTHENTICATED
  EXPECT_NE(no_token.grpc_message().find("x-filigree-token"), std::string::npos) << no_token.grpc_message();

  const Reply wrong = call("JoinSession", req, auth(id, "not-a-token"));
  EXPECT_EQ(wrong.grpc_status(), 5);  // NOT_FOUND: a wrong token hears what an unknown id hears

  const Reply viewer_closes = call("CloseSession", v1::CloseSessionRequest(), auth(id, created.viewer_token()));
  EXPECT_EQ(viewer_closes.grpc_status(), 7);

  v1::JoinSessionRequest unknown;
  unknown.set_session_id("no-such-session");
  const Reply missing = call("JoinSession", unknown, auth("no-such-session", created.viewer_token()));
  EXPECT_EQ(missing.grpc_status(), 5);  // NOT_FOUND
  // Not a session id: described, not echoed (a client's id may be megabytes).
  EXPECT_NE(missing.grpc_message().find("no session (a malformed id of 15 bytes"), std::string::npos) << missing.grpc_message();

  // grpc-message is percent-encoded on the wire: printable ASCII only.
  v1::SetOptionsRequest bad;
  bad.set_session_id(id);
  bad.set_threshold(-1.0);
  const Reply invalid = call("SetOptions", bad, auth(id, created.editor_token()));
  EXPECT_EQ(invalid.grpc_status(), 3);
  const std::string raw = invalid.trailer.count("grpc-message") ? invalid.trailer.at("grpc-message") : "";
  EXPECT_FALSE(raw.empty());
  for (const char c : raw) EXPECT_TRUE(c >= 0x20 && c <= 0x7e) << raw;
  EXPECT_NE(invalid.grpc_message().find("threshold"), std::string::npos) << invalid.grpc_message();
}

TEST_F(GrpcWebTest, StreamingRequestMethodsAndUnknownOnesAreUnimplemented) {
  for (const char* method : {"Drive", "Follow"}) {
    const Reply r = call(method, v1::DriveRequest(), {});
    EXPECT_EQ(r.http_status, 200u);
    EXPECT_TRUE(r.one_trailer_last);
    EXPECT_EQ(r.grpc_status(), 12) << method;
    EXPECT_NE(r.grpc_message().find("SubmitPose"), std::string::npos) << r.grpc_message();
  }
  EXPECT_EQ(call("NoSuchMethod", v1::DriveRequest(), {}).grpc_status(), 12);

  HttpClient client(server_->http_address());
  auto req = grpc_web_request("ListSessions", frame_bytes(0, ""), {});
  req.set(bhttp::field::content_type, "application/json");
  EXPECT_EQ(client.exchange(req).result_int(), 415u);
}

// A page uploads a mesh: CreateSession's messages (begin, then chunks) in
// one body; the answer streams the progress and then the session. Other
// methods keep the 4 MiB body bound and their one message.
TEST_F(GrpcWebTest, ABrowserUploadsAMeshInOneBodyAndGetsProgressAndItsSession) {
  const std::string bytes = file_bytes(test::shipped_path("bunny_small.obj"));
  v1::CreateSessionRequest begin;
  begin.mutable_begin()->set_format("obj");
  begin.mutable_begin()->set_total_bytes(bytes.size());
  begin.mutable_begin()->mutable_options()->set_base_vertices(150);
  std::string body = frame_bytes(0, begin.SerializeAsString());
  for (std::size_t at = 0; at < bytes.size(); at += bytes.size() / 2 + 1) {
    v1::CreateSessionRequest chunk;
    chunk.set_chunk(bytes.substr(at, bytes.size() / 2 + 1));
    body += frame_bytes(0, chunk.SerializeAsString());
  }
  HttpClient client(server_->http_address());
  const Reply r = to_reply(client.exchange(grpc_web_request("CreateSession", body, {})));
  EXPECT_EQ(r.grpc_status(), 0) << r.grpc_message();
  EXPECT_TRUE(r.one_trailer_last);
  int progress = 0;
  v1::CreateSessionResponse::Created created;
  for (const std::string& m : r.messages) {
    v1::CreateSessionResponse response;
    ASSERT_TRUE(response.ParseFromString(m));
    progress += response.has_progress();
    if (response.has_created()) created = response.created();
  }
  EXPECT_GE(progress, 1);
  ASSERT_FALSE(created.editor_token().empty());
  EXPECT_EQ(created.info().base().original_ids_size(), 150);
  // The session is a session like any: native clients join it with its token.
  v1::JoinSessionRequest join;
  join.set_session_id(created.info().session_id());
  EXPECT_EQ(call("JoinSession", join, auth(created.info().session_id(), created.editor_token())).grpc_status(), 0);

  // A unary method takes one message, within the ordinary bound.
  // (A streamed answer ends its connection: a new one.)
  EXPECT_EQ(to_reply(HttpClient(server_->http_address())
                         .exchange(grpc_web_request("JoinSession", frame_bytes(0, "") + frame_bytes(0, ""), {})))
                .grpc_status(),
            3);
  const Reply big = to_reply(HttpClient(server_->http_address())
                                 .exchange(grpc_web_request("JoinSession", frame_bytes(0, std::string(5u << 20, 'x')), {})));
  EXPECT_EQ(big.grpc_status(), 8) << big.grpc_message();  // RESOURCE_EXHAUSTED
}

TEST_F(GrpcWebTest, CorsPreflightAllowsTheGrpcWebHeaders) {
  HttpClient client(server_->http_address());
  bhttp::request<bhttp::string_body> req{bhttp::verb::options, "/filigree.v1.Filigree/JoinSession", 11};
  req.set(bhttp::field::host, "localhost");
  req.set(bhttp::field::origin, "http://localhost:5173");
  req.set(bhttp::field::access_control_request_method, "POST");
  req.set(bhttp::field::access_control_request_headers, "content-type,x-filigree-token,x-grpc-web,x-session-id,x-user-agent");
  const auto res = client.exchange(req);
  EXPECT_GE(res.result_int(), 200u);
  EXPECT_LT(res.result_int(), 300u);
  // The origin given with --http-cors-origin, and no other.
  EXPECT_EQ(std::string(res[bhttp::field::access_control_allow_origin]), "http://localhost:5173");
  EXPECT_NE(std::string(res[bhttp::field::access_control_allow_methods]).find("POST"), std::string::npos);
  const std::string allowed(res[bhttp::field::access_control_allow_headers]);
  for (const char* h : {"content-type", "x-grpc-web", "x-user-agent", "grpc-timeout", "x-filigree-token",
                        "x-filigree-api-key", "x-session-id"})
    EXPECT_NE(allowed.find(h), std::string::npos) << h << " not in " << allowed;
  const std::string exposed(res[bhttp::field::access_control_expose_headers]);
  EXPECT_NE(exposed.find("grpc-status"), std::string::npos);
  EXPECT_NE(exposed.find("grpc-message"), std::string::npos);

  // The connection stays usable (keep-alive) for the actual request.
  const Reply r = to_reply(client.exchange(grpc_web_request("ListSessions", frame_bytes(0, ""), {})));
  EXPECT_EQ(r.grpc_status(), 0);
  EXPECT_EQ(r.messages.size(), 1u);

  // Another origin's page is not allowed.
  req.set(bhttp::field::origin, "https://elsewhere.example");
  const auto refused = client.exchange(req);
  EXPECT_EQ(refused.result_int(), 403u);
  EXPECT_EQ(std::string(refused[bhttp::field::access_control_allow_origin]), "");
}

// A browser can present an API key (x-filigree-api-key): the bridge forwards
// it to the service, which then lets it list sessions.
TEST(GrpcWebApiKeys, ABrowserCallWithTheApiKeyHeaderIsAuthorised) {
  const std::filesystem::path keys = std::filesystem::path(::testing::TempDir()) /
                                     ("filigree_web_keys_" + std::to_string(::getpid()));
  // SHA-256 of "browser-api-key-7d2a".
  std::ofstream(keys) << "browser 903a0e0661a55b86c709123e9daa29ec5d3048d35b96eb3870f3c22f070f435d\n";
  ServerProcess server(FILIGREE_SERVER_BINARY, {"--api-keys", keys.string()}, /*http=*/true);
  const auto list = [&](const Headers& headers) {
    HttpClient client(server.http_address());
    return to_reply(client.exchange(grpc_web_request("ListSessions", frame_bytes(0, ""), headers)));
  };
  EXPECT_EQ(list({}).grpc_status(), 16);  // UNAUTHENTICATED
  EXPECT_EQ(list({{"x-filigree-api-key", "not-the-key"}}).grpc_status(), 7);  // PERMISSION_DENIED
  const Reply r = list({{"x-filigree-api-key", "browser-api-key-7d2a"}});
  EXPECT_EQ(r.grpc_status(), 0) << r.grpc_message();
  std::filesystem::remove(keys);
}

TEST_F(GrpcWebTest, WatchStreamsFramesAsTheyComeAndEndsOnShutdown) {
  const auto created = upload();
  const std::string id = created.info().session_id();

  HttpClient watch(server_->http_address());
  v1::WatchRequest wr;
  wr.set_session_id(id);
  watch.write(grpc_web_request("Watch", frame_bytes(0, wr.SerializeAsString()), auth(id, created.viewer_token())));
  const auto& head = watch.read_stream_header();
  EXPECT_EQ(head.result_int(), 200u);
  EXPECT_EQ(std::string(head[bhttp::field::content_type]), "application/grpc-web+proto");
  EXPECT_TRUE(head.chunked());

  // The current frame at once: the rest frame.
  std::optional<Frame> f = watch.next_frame();
  ASSERT_TRUE(f);
  ASSERT_EQ(f->flags, 0);
  v1::Frame first;
  ASSERT_TRUE(first.ParseFromString(f->payload));
  EXPECT_EQ(first.version(), 0u);
  EXPECT_EQ(first.vertex_count(), 1839u);

  // A pose through gRPC-Web (unary SubmitPose): every base vertex moved up.
  v1::DriveRequest pose;
  pose.set_session_id(id);
  pose.set_pose_id(1);
  pose.set_client_name("browser");
  const auto& base = created.info().base().positions();
  for (int i = 0; i < base.size(); ++i) pose.add_positions(base[i] + (i % 3 == 1 ? 0.01f : 0.0f));
  const Reply submitted = call("SubmitPose", pose, auth(id, created.editor_token()));
  ASSERT_EQ(submitted.grpc_status(), 0) << submitted.grpc_message();
  ASSERT_EQ(submitted.messages.size(), 1u);
  v1::SubmitPoseResponse accepted;
  ASSERT_TRUE(accepted.ParseFromString(submitted.messages[0]));
  EXPECT_EQ(accepted.accepted_at_version(), 0u);

  // The frame that includes it arrives on the open stream.
  f = watch.next_frame();
  ASSERT_TRUE(f);
  ASSERT_EQ(f->flags, 0);
  v1::Frame second;
  ASSERT_TRUE(second.ParseFromString(f->payload));
  EXPECT_GE(second.version(), 1u);
  EXPECT_FALSE(second.deltas().empty());
  ASSERT_GE(second.changes_size(), 1);
  EXPECT_EQ(second.changes(0).client_name(), "browser");

  // SIGTERM: the stream ends with a trailer (UNAVAILABLE) and a complete
  // chunked body, and the server exits cleanly. (The native channel goes
  // first: the gRPC server's shutdown waits for its connections to close.)
  stub_.reset();
  auto exit_code = std::async(std::launch::async, [&] { return server_->terminate(); });
  std::optional<Frame> last;
  while (auto g = watch.next_frame()) {
    last = g;
    if (g->trailer()) break;
    EXPECT_EQ(g->flags, 0);
  }
  ASSERT_TRUE(last && last->trailer());
  EXPECT_EQ(std::stoi(parse_trailer(last->payload).at("grpc-status")), 14);
  EXPECT_FALSE(watch.next_frame());  // nothing after the trailer, and the body ended
  watch.close();
  EXPECT_EQ(exit_code.get(), 0);
}

TEST_F(GrpcWebTest, ABrowserThatGoesAwayCancelsItsWatch) {
  const auto created = upload();
  const std::string id = created.info().session_id();
  {
    HttpClient watch(server_->http_address());
    v1::WatchRequest wr;
    wr.set_session_id(id);
    watch.write(grpc_web_request("Watch", frame_bytes(0, wr.SerializeAsString()), auth(id, created.viewer_token())));
    watch.read_stream_header();
    ASSERT_TRUE(watch.next_frame());
    EXPECT_EQ(watchers(id), 1u);
    watch.close();
  }
  // The server notices the closed connection while idle and cancels the upstream Watch.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  std::uint32_t n = 1;
  while ((n = watchers(id)) != 0 && std::chrono::steady_clock::now() < deadline) std::this_thread::yield();
  EXPECT_EQ(n, 0u);
}

TEST_F(GrpcWebTest, MalformedBodiesAreInvalidArgumentAndTheServerKeepsAnswering) {
  HttpClient client(server_->http_address());
  const auto send = [&](const std::string& body) {
    return to_reply(client.exchange(grpc_web_request("ListSessions", body, {})));
  };
  for (const std::string& body : {std::string("garbage, not a gRPC-Web body"), std::string(),
                                  std::string("\0\0\0", 3), frame_bytes(0, "").substr(0, 4),
                                  frame_bytes(0, "abc").substr(0, 6), frame_bytes(0, "") + frame_bytes(0, ""),
                                  std::string("\0\xff\xff\xff\xff", 5), frame_bytes(0x80, "grpc-status:0\r\n")}) {
    const Reply r = send(body);
    EXPECT_EQ(r.http_status, 200u);
    EXPECT_TRUE(r.one_trailer_last);
    EXPECT_EQ(r.grpc_status(), 3) << "body of " << body.size() << " bytes: " << r.grpc_message();
  }
  EXPECT_EQ(send(frame_bytes(1, "")).grpc_status(), 12);  // compressed: not supported
  // A malformed grpc-timeout; a valid one.
  EXPECT_EQ(to_reply(client.exchange(grpc_web_request("ListSessions", frame_bytes(0, ""), {{"grpc-timeout", "soon"}})))
                .grpc_status(),
            3);
  const Reply ok = to_reply(client.exchange(grpc_web_request("ListSessions", frame_bytes(0, ""), {{"grpc-timeout", "10S"}})));
  EXPECT_EQ(ok.grpc_status(), 0) << ok.grpc_message();
  EXPECT_EQ(ok.messages.size(), 1u);
  // The longest timeout the format allows (8 digits of hours) overflows
  // int64 nanoseconds: it must mean "no hurry", not a deadline in the past
  // (found by fuzz_grpc_web).
  const Reply longest =
      to_reply(client.exchange(grpc_web_request("ListSessions", frame_bytes(0, ""), {{"grpc-timeout", "99999999H"}})));
  EXPECT_EQ(longest.grpc_status(), 0) << longest.grpc_message();

  // Bytes that are not HTTP at all: the connection is dropped, the server lives on.
  {
    HttpClient junk(server_->http_address());
    junk.write_raw("\x16\x03\x01 this is not HTTP\r\n\r\n");
  }
  // Over the body limit (4 MiB): RESOURCE_EXHAUSTED, and the connection closes.
  {
    HttpClient big(server_->http_address());
    const Reply r = to_reply(big.exchange(grpc_web_request("ListSessions", frame_bytes(0, std::string(5u << 20, 'x')), {})));
    EXPECT_EQ(r.grpc_status(), 8) << r.grpc_message();
  }
  const Reply after = call("ListSessions", v1::ListSessionsRequest(), {});
  EXPECT_EQ(after.grpc_status(), 0);
}

TEST_F(GrpcWebTest, ServesTheWebViewerFilesAndNothingElse) {
  HttpClient client(server_->http_address());
  const auto get = [&](const std::string& target, bhttp::verb verb = bhttp::verb::get) {
    bhttp::request<bhttp::string_body> req{verb, target, 11};
    req.set(bhttp::field::host, "localhost");
    return client.exchange(req);
  };
  auto res = get("/");
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_EQ(res.body(), "<!doctype html><title>Filigree</title>");
  EXPECT_EQ(std::string(res[bhttp::field::content_type]).rfind("text/html", 0), 0u);
  EXPECT_EQ(get("/index.html").body(), res.body());

  res = get("/assets/app.js?v=3");
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_EQ(std::string(res[bhttp::field::content_type]).rfind("text/javascript", 0), 0u);
  EXPECT_EQ(std::string(get("/assets/style.css")[bhttp::field::content_type]).rfind("text/css", 0), 0u);
  res = get("/assets/draco.wasm");
  EXPECT_EQ(std::string(res[bhttp::field::content_type]), "application/wasm");
  EXPECT_EQ(res.body().size(), 8u);

  res = get("/assets/app.js", bhttp::verb::head);
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_EQ(std::string(res[bhttp::field::content_length]), "20");

  EXPECT_EQ(get("/missing.html", bhttp::verb::head).result_int(), 404u);
  EXPECT_EQ(get("/").result_int(), 200u);  // that HEAD answer had no body: the connection is still in step
  EXPECT_EQ(get("/missing.html").result_int(), 404u);
  EXPECT_EQ(get("/assets/").result_int(), 404u);  // a directory without index.html

  // What a page tells its user about reaching this server from a program.
  res = get("/server.json");
  EXPECT_EQ(std::string(res[bhttp::field::content_type]), "application/json");
  const std::string port = server_->address().substr(server_->address().rfind(':') + 1);
  EXPECT_EQ(res.body(), "{\"grpc_host\":\"127.0.0.1\",\"grpc_port\":" + port + ",\"tls\":false,\"api_keys\":false}");
  for (const char* escape : {"/../secret.txt", "/assets/../../secret.txt", "/%2e%2e/secret.txt", "/..%2fsecret.txt",
                             "/../../../../etc/passwd", "/assets/%2E%2E/%2E%2E/etc/passwd"}) {
    res = get(escape);
    EXPECT_TRUE(res.result_int() == 400u || res.result_int() == 404u) << escape << " → " << res.result_int();
    EXPECT_EQ(res.body().find("outside the web root"), std::string::npos) << escape;
    EXPECT_EQ(res.body().find("root:"), std::string::npos) << escape;
  }
  EXPECT_EQ(get("/", bhttp::verb::delete_).result_int(), 405u);
}

}  // namespace
}  // namespace filigree
