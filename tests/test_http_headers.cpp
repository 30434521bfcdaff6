// What the browser port says and logs about secrets and origins:
//  - log lines (trace level included) never show a token or an API key,
//    from the request target (the viewer's /?session=…&token=…) or headers;
//  - every response carries Referrer-Policy: no-referrer and
//    X-Content-Type-Options: nosniff (Strict-Transport-Security is HTTPS's:
//    test_https.cpp);
//  - CORS only for configured origins (HttpOptions::cors_origins): none by
//    default; the preflight of an allowed one lets browsers send
//    x-filigree-api-key, and the bridge forwards it to the service.
//
// In-process: the HTTP server in front of a gRPC server with a fake
// filigree.v1.Filigree; raw sockets.

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "server/http/http_server.h"
#include "server/http/log_redaction.h"
#include "support/grpc_web_frames.h"
#include "support/raw_socket.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::Clock;
using test::RawSocket;
using test::read_response;

constexpr char kIndex[] = "<!doctype html><title>Filigree</title>";
constexpr char kApiKey[] = "api-key-4f1c9e";
constexpr char kToken[] = "c0ffee0123456789abcdef0123456789";
constexpr auto kPatience = 5s;

// ListSessions answers one session named after whether the API key arrived as metadata.
class KeyEcho final : public v1::Filigree::Service {
  grpc::Status ListSessions(grpc::ServerContext* ctx, const v1::ListSessionsRequest*, v1::ListSessionsResponse* out) override {
    const auto& md = ctx->client_metadata();
    const auto key = md.find("x-filigree-api-key");
    if (key == md.end() || std::string(key->second.data(), key->second.size()) != kApiKey)
      return {grpc::StatusCode::UNAUTHENTICATED, "no API key"};
    out->add_sessions()->set_session_id("seen-the-key");
    return grpc::Status::OK;
  }
};

// The log at trace level into a string, for one test.
class CapturedLog {
 public:
  CapturedLog() : previous_(spdlog::default_logger()) {
    auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(text_);
    auto logger = std::make_shared<spdlog::logger>("captured", sink);
    logger->set_level(spdlog::level::trace);
    logger->flush_on(spdlog::level::trace);
    spdlog::set_default_logger(logger);
  }
  ~CapturedLog() { spdlog::set_default_logger(previous_); }
  std::string text() {
    spdlog::default_logger()->flush();
    return text_.str();
  }

 private:
  std::shared_ptr<spdlog::logger> previous_;
  std::ostringstream text_;
};

class HttpHeadersTest : public ::testing::Test {
 protected:
  void SetUp() override {
    www_ = fs::path(::testing::TempDir()) / ("filigree_http_headers_" + std::to_string(::getpid()) + "_" +
                                             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(www_);
    fs::create_directories(www_);
    std::ofstream(www_ / "index.html") << kIndex;
    grpc::ServerBuilder builder;
    builder.RegisterService(&service_);
    grpc_server_ = builder.BuildAndStart();
    ASSERT_TRUE(grpc_server_);
    options_.listen = "127.0.0.1:0";
    options_.web_root = www_;
    options_.grpc_web_services = {v1::Filigree::service_full_name()};
  }
  void TearDown() override {
    http_.reset();
    if (grpc_server_) grpc_server_->Shutdown();
    fs::remove_all(www_);
  }
  void start() {
    http_ = std::make_unique<server::http::HttpServer>(options_, grpc_server_->InProcessChannel(grpc::ChannelArguments()));
  }

  // One request on a new connection; its response, checked to have come.
  test::HttpResponse exchange(const std::string& request) {
    RawSocket socket(http_->address());
    EXPECT_TRUE(socket.send(request));
    auto res = read_response(socket, Clock::now() + kPatience);
    EXPECT_TRUE(res) << "no response to " << request;
    return res ? *res : test::HttpResponse{};
  }

  static std::string grpc_web_post(const std::string& method, const std::vector<std::string>& headers) {
    const std::string body = test::frame_bytes(0, "");
    std::string req = "POST /filigree.v1.Filigree/" + method + " HTTP/1.1\r\nHost: localhost\r\n"
                      "Content-Type: application/grpc-web+proto\r\nX-Grpc-Web: 1\r\nContent-Length: " +
                      std::to_string(body.size()) + "\r\n";
    for (const auto& h : headers) req += h + "\r\n";
    return req + "\r\n" + body;
  }

  static std::string preflight(const std::string& origin) {
    return "OPTIONS /filigree.v1.Filigree/ListSessions HTTP/1.1\r\nHost: localhost\r\nOrigin: " + origin +
           "\r\nAccess-Control-Request-Method: POST\r\nAccess-Control-Request-Headers: content-type,x-filigree-api-key,"
           "x-grpc-web\r\n\r\n";
  }

  static std::string header(const test::HttpResponse& res, const std::string& name) {
    const auto it = res.headers.find(name);
    return it == res.headers.end() ? std::string() : it->second;
  }

  fs::path www_;
  KeyEcho service_;
  std::unique_ptr<grpc::Server> grpc_server_;
  server::http::HttpOptions options_;
  std::unique_ptr<server::http::HttpServer> http_;
};

// ------------------------------------------------------------ logs

TEST(LogRedaction, SecretQueryValuesAreRedactedAndTheRestKept) {
  using server::http::redacted_target;
  EXPECT_EQ(redacted_target("/?session=abc&token=s3cret"), "/?session=abc&token=REDACTED");
  EXPECT_EQ(redacted_target("/index.html"), "/index.html");
  EXPECT_EQ(redacted_target("/?TOKEN=a&x=1&api_key=b&apikey=c&x-filigree-api-key=d&access_token=e&password=f"),
            "/?TOKEN=REDACTED&x=1&api_key=REDACTED&apikey=REDACTED&x-filigree-api-key=REDACTED&access_token=REDACTED&"
            "password=REDACTED");
  // What a browser's URLSearchParams reads as "token" is redacted too.
  EXPECT_EQ(redacted_target("/?%74oken=s3cret"), "/?%74oken=REDACTED");
  EXPECT_EQ(redacted_target("/?session=a&token=s3cret#frag"), "/?session=a&token=REDACTED#…");
  EXPECT_EQ(redacted_target("/?token"), "/?token");  // no value, nothing to hide
  EXPECT_EQ(redacted_target("/?a=1&&token=x&"), "/?a=1&&token=REDACTED&");
  const std::string long_target = "/?session=" + std::string(4000, 'a') + "&token=s3cret";
  const std::string logged = redacted_target(long_target);
  EXPECT_LE(logged.size(), server::http::kLoggedTargetBytes + 4);
  EXPECT_EQ(logged.find("s3cret"), std::string::npos);
  EXPECT_TRUE(server::http::is_secret_header("x-filigree-token"));
  EXPECT_TRUE(server::http::is_secret_header("x-filigree-api-key"));
  EXPECT_TRUE(server::http::is_secret_header("authorization"));
  EXPECT_FALSE(server::http::is_secret_header("x-session-id"));
}

TEST_F(HttpHeadersTest, NoLogLineShowsATokenOrAnApiKeyAtTraceLevel) {
  CapturedLog log;
  start();
  // The viewer's address as a browser asks for it.
  EXPECT_EQ(exchange("GET /?session=abc&token=" + std::string(kToken) + " HTTP/1.1\r\nHost: localhost\r\n\r\n").status, 200);
  EXPECT_EQ(exchange("GET /missing?token=" + std::string(kToken) + " HTTP/1.1\r\nHost: localhost\r\n\r\n").status, 404);
  // gRPC-Web with both secrets in headers.
  EXPECT_EQ(exchange(grpc_web_post("ListSessions", {"X-Filigree-Token: " + std::string(kToken),
                                                    "X-Filigree-Api-Key: " + std::string(kApiKey)}))
                .status,
            200);
  const std::string text = log.text();
  EXPECT_NE(text.find("session=abc&token=REDACTED"), std::string::npos) << text;
  EXPECT_EQ(text.find(kToken), std::string::npos) << text;
  EXPECT_EQ(text.find(kApiKey), std::string::npos) << text;
}

// ------------------------------------------------------------ security headers

TEST_F(HttpHeadersTest, EveryResponseSaysNoReferrerAndNoSniffing) {
  start();
  for (const std::string& req :
       {std::string("GET /index.html HTTP/1.1\r\nHost: localhost\r\n\r\n"), std::string("GET /nothing HTTP/1.1\r\nHost: localhost\r\n\r\n"),
        std::string("DELETE / HTTP/1.1\r\nHost: localhost\r\n\r\n"), grpc_web_post("ListSessions", {}),
        grpc_web_post("ListSessions", {"X-Filigree-Api-Key: " + std::string(kApiKey)}),
        std::string("OPTIONS / HTTP/1.1\r\nHost: localhost\r\n\r\n")}) {
    SCOPED_TRACE(req.substr(0, req.find('\r')));
    const auto res = exchange(req);
    EXPECT_NE(res.status, 0);
    EXPECT_EQ(header(res, "referrer-policy"), "no-referrer");
    EXPECT_EQ(header(res, "x-content-type-options"), "nosniff");
    EXPECT_EQ(header(res, "strict-transport-security"), "") << "HSTS over plaintext HTTP is meaningless";
  }
}

// ------------------------------------------------------------ CORS

TEST_F(HttpHeadersTest, WithoutConfiguredOriginsNoCrossOriginAccessIsGranted) {
  start();
  // Same origin (the viewer): no CORS needed, the call works.
  auto res = exchange(grpc_web_post("ListSessions", {"X-Filigree-Api-Key: " + std::string(kApiKey)}));
  EXPECT_EQ(res.status, 200);
  EXPECT_NE(res.body.find("grpc-status:0"), std::string::npos);
  EXPECT_EQ(header(res, "access-control-allow-origin"), "");
  // A page of another origin gets no grant, and its preflight is refused.
  res = exchange(grpc_web_post("ListSessions", {"Origin: https://evil.example"}));
  EXPECT_EQ(header(res, "access-control-allow-origin"), "");
  res = exchange(preflight("https://evil.example"));
  EXPECT_EQ(res.status, 403);
  EXPECT_EQ(header(res, "access-control-allow-origin"), "");
  EXPECT_EQ(header(res, "access-control-allow-headers"), "");
}

TEST_F(HttpHeadersTest, AConfiguredOriginMayCallWithAnApiKeyAndOthersMayNot) {
  options_.cors_origins = {"https://app.example", "http://localhost:5173"};
  start();
  auto res = exchange(preflight("https://app.example"));
  EXPECT_EQ(res.status, 204);
  EXPECT_EQ(header(res, "access-control-allow-origin"), "https://app.example");
  EXPECT_EQ(header(res, "vary"), "Origin");
  const std::string allowed = header(res, "access-control-allow-headers");
  for (const char* h : {"content-type", "x-grpc-web", "x-filigree-token", "x-filigree-api-key", "x-session-id"})
    EXPECT_NE(allowed.find(h), std::string::npos) << h << " not in " << allowed;
  // The call itself: granted, and the key reaches the service.
  res = exchange(grpc_web_post("ListSessions", {"Origin: http://localhost:5173", "X-Filigree-Api-Key: " + std::string(kApiKey)}));
  EXPECT_EQ(res.status, 200);
  EXPECT_EQ(header(res, "access-control-allow-origin"), "http://localhost:5173");
  EXPECT_NE(header(res, "access-control-expose-headers").find("grpc-status"), std::string::npos);
  EXPECT_NE(res.body.find("seen-the-key"), std::string::npos) << "the API key did not reach the service";
  EXPECT_NE(res.body.find("grpc-status:0"), std::string::npos);
  // Another origin: nothing granted.
  res = exchange(preflight("https://app.example.evil"));
  EXPECT_EQ(res.status, 403);
  res = exchange(grpc_web_post("ListSessions", {"Origin: https://other.example"}));
  EXPECT_EQ(header(res, "access-control-allow-origin"), "");
  EXPECT_EQ(header(res, "vary"), "Origin");
}

TEST_F(HttpHeadersTest, AnyOriginOnlyWhenAskedFor) {
  options_.cors_origins = {"*"};
  start();
  const auto res = exchange(preflight("https://anywhere.example"));
  EXPECT_EQ(res.status, 204);
  EXPECT_EQ(header(res, "access-control-allow-origin"), "*");
}

TEST_F(HttpHeadersTest, AnOriginThatCouldNeverMatchIsRefusedAtStart) {
  for (const char* bad : {"https://app.example/", "app.example", "https://app.example/path", "ftp://x"}) {
    options_.cors_origins = {bad};
    EXPECT_THROW(start(), std::runtime_error) << bad;
  }
}

}  // namespace
}  // namespace filigree
