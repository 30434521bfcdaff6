// The browser port's bounds on what a client may hold (HttpOptions): the
// header, body and idle keep-alive timeouts, each a deadline for its whole
// phase, so that a client sending a byte at a time (slowloris) is closed
// like one sending nothing, while other clients are served meanwhile; the
// header and body size limits (431, 413, RESOURCE_EXHAUSTED for gRPC-Web);
// keep-alive and its request count; the cap on open connections.
//
// In-process: the HTTP server in front of a gRPC server with an empty
// filigree.v1.Filigree (the transport is under test, not the service).
// Timeouts are short (hundreds of milliseconds). Nothing waits by sleeping:
// each test reads until the server closes, under a generous deadline, and
// checks when that happened against wide bounds (not before 3/4 of the
// timeout, well within 5 s).

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "server/http/http_server.h"
#include "support/raw_socket.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::Clock;
using test::RawSocket;
using test::read_response;

constexpr char kIndex[] = "<!doctype html><title>Filigree</title>";
// How long any test waits for what must happen; far above every timeout here.
constexpr auto kPatience = 5s;

std::string get(const std::string& target = "/index.html") {
  return "GET " + target + " HTTP/1.1\r\nHost: localhost\r\n\r\n";
}

// Whether the time from `from` to `to` is the timeout `t` as seen from a
// client: not early (a quarter off for clock granularity), not late beyond
// kPatience.
::testing::AssertionResult took_about(Clock::time_point from, Clock::time_point to, std::chrono::milliseconds t) {
  const auto took = std::chrono::duration_cast<std::chrono::milliseconds>(to - from);
  if (took < t * 3 / 4 || took >= kPatience)
    return ::testing::AssertionFailure() << "closed after " << took.count() << " ms; the timeout is " << t.count() << " ms";
  return ::testing::AssertionSuccess() << "closed after " << took.count() << " ms";
}

class HttpLimitsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    www_ = fs::path(::testing::TempDir()) /
           ("filigree_http_limits_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(www_);
    fs::create_directories(www_);
    std::ofstream(www_ / "index.html") << kIndex;
    grpc::ServerBuilder builder;
    builder.RegisterService(&service_);
    grpc_server_ = builder.BuildAndStart();
    ASSERT_TRUE(grpc_server_);
    // Long unless a test is about them: only the bound under test can close.
    options_.listen = "127.0.0.1:0";
    options_.web_root = www_;
    options_.grpc_web_services = {v1::Filigree::service_full_name()};
    options_.idle_timeout = 30s;
    options_.header_timeout = 30s;
    options_.body_timeout = 30s;
  }

  void TearDown() override {
    http_.reset();
    if (grpc_server_) grpc_server_->Shutdown();
    fs::remove_all(www_);
  }

  void start() {
    http_ = std::make_unique<server::http::HttpServer>(options_, grpc_server_->InProcessChannel(grpc::ChannelArguments()));
  }

  std::unique_ptr<RawSocket> connect() { return std::make_unique<RawSocket>(http_->address()); }

  // GET /index.html on `socket`, checked: 200, the file, kept alive.
  static void expect_index(RawSocket& socket) {
    ASSERT_TRUE(socket.send(get()));
    const auto res = read_response(socket, Clock::now() + kPatience);
    ASSERT_TRUE(res);
    EXPECT_EQ(res->status, 200);
    EXPECT_EQ(res->body, kIndex);
    EXPECT_TRUE(res->keep_alive());
  }

  fs::path www_;
  v1::Filigree::Service service_;  // every method UNIMPLEMENTED
  std::unique_ptr<grpc::Server> grpc_server_;
  server::http::HttpOptions options_;
  std::unique_ptr<server::http::HttpServer> http_;
};

// ------------------------------------------------------------ timeouts

TEST_F(HttpLimitsTest, SlowlorisClientsAreClosedAtTheHeaderTimeoutWhileOthersAreServed) {
  options_.header_timeout = 1000ms;
  options_.threads = 1;  // one I/O thread: the slow clients must not hold it
  start();

  // Three clients each send a header one byte every 20 ms: each byte far
  // within any per-read timeout, the header never complete within 1 s.
  constexpr int kSlow = 3;
  std::vector<std::unique_ptr<RawSocket>> slow;
  for (int i = 0; i < kSlow; ++i) slow.push_back(connect());
  const std::string header = "GET /index.html HTTP/1.1\r\nHost: localhost\r\nX-Padding: " + std::string(4000, 'a');
  const Clock::time_point first_byte = Clock::now();
  // jthread: stopped and joined however the test ends.
  std::jthread trickle([&](std::stop_token stop) {
    std::vector<bool> open(kSlow, true);
    for (std::size_t at = 0; at < header.size() && !stop.stop_requested(); ++at) {
      for (int i = 0; i < kSlow; ++i)
        if (open[i]) open[i] = slow[i]->send(header.substr(at, 1));
      std::this_thread::sleep_for(20ms);  // the pace of the attack, not a synchronisation
    }
  });

  // Meanwhile another client is served normally, on a connection of its own.
  auto normal = connect();
  expect_index(*normal);
  const Clock::time_point served = Clock::now();

  for (int i = 0; i < kSlow; ++i) {
    ASSERT_TRUE(slow[i]->read_until_closed(first_byte + kPatience)) << "slow client " << i << " still open";
    EXPECT_TRUE(took_about(first_byte, slow[i]->closed_at(), options_.header_timeout)) << "slow client " << i;
    EXPECT_EQ(slow[i]->received(), "") << "a timeout has no answer";
    EXPECT_LT(served, slow[i]->closed_at()) << "the normal client was served while the slow ones were open";
  }
  expect_index(*normal);  // and still is
}

TEST_F(HttpLimitsTest, AClientThatTricklesItsBodyIsClosedAtTheBodyTimeout) {
  options_.body_timeout = 500ms;
  start();
  auto client = connect();
  ASSERT_TRUE(client->send(
      "POST /upload HTTP/1.1\r\nHost: localhost\r\nContent-Type: text/plain\r\nContent-Length: 100000\r\n\r\n"));
  const Clock::time_point header_sent = Clock::now();
  std::jthread trickle([&](std::stop_token stop) {
    // A byte every 20 ms: 100000 bytes would take half an hour.
    while (!stop.stop_requested() && client->send("x")) std::this_thread::sleep_for(20ms);  // the pace, not a synchronisation
  });
  ASSERT_TRUE(client->read_until_closed(header_sent + kPatience));
  EXPECT_TRUE(took_about(header_sent, client->closed_at(), options_.body_timeout));
  EXPECT_EQ(client->received(), "");
  expect_index(*connect());  // the server goes on
}

TEST_F(HttpLimitsTest, KeptAliveConnectionsServeSeveralRequestsThenCloseWhenIdle) {
  options_.idle_timeout = 600ms;
  options_.header_timeout = 100ms;  // shorter than idle: an idle connection is not cut by it
  start();
  auto client = connect();
  for (int i = 0; i < 3; ++i) expect_index(*client);
  // Pipelined: two requests in one write, two answers in order.
  ASSERT_TRUE(client->send(get() + get("/missing.js")));
  const auto first = read_response(*client, Clock::now() + kPatience);
  const auto second = read_response(*client, Clock::now() + kPatience);
  ASSERT_TRUE(first && second);
  EXPECT_EQ(first->status, 200);
  EXPECT_EQ(second->status, 404);
  EXPECT_TRUE(second->keep_alive());
  const Clock::time_point last = Clock::now();
  ASSERT_TRUE(client->read_until_closed(last + kPatience));
  EXPECT_TRUE(took_about(last, client->closed_at(), options_.idle_timeout));
  EXPECT_EQ(client->received(), "");

  // A connection that never sends a byte: the idle timeout too, not the header's.
  auto silent = connect();
  const Clock::time_point connected = Clock::now();
  ASSERT_TRUE(silent->read_until_closed(connected + kPatience));
  EXPECT_TRUE(took_about(connected, silent->closed_at(), options_.idle_timeout));
}

TEST_F(HttpLimitsTest, TheLastRequestAllowedOnAConnectionSaysCloseAndTheConnectionEnds) {
  options_.max_requests_per_connection = 3;
  start();
  auto client = connect();
  expect_index(*client);
  expect_index(*client);
  ASSERT_TRUE(client->send(get()));
  const auto third = read_response(*client, Clock::now() + kPatience);
  ASSERT_TRUE(third);
  EXPECT_EQ(third->status, 200);
  EXPECT_EQ(third->body, kIndex);
  EXPECT_FALSE(third->keep_alive());
  // Closed by the server at once, not by the (30 s) idle timeout.
  const Clock::time_point answered = Clock::now();
  ASSERT_TRUE(client->read_until_closed(answered + kPatience));
  EXPECT_LT(client->closed_at() - answered, kPatience);
  expect_index(*connect());
}

// ------------------------------------------------------------ sizes

TEST_F(HttpLimitsTest, AHeaderOverTheLimitGets431AndTheConnectionCloses) {
  options_.max_header_bytes = 1024;
  start();
  // Within the limit: served.
  auto fits = connect();
  ASSERT_TRUE(fits->send("GET /index.html HTTP/1.1\r\nHost: localhost\r\nX-Padding: " + std::string(512, 'a') + "\r\n\r\n"));
  const auto ok = read_response(*fits, Clock::now() + kPatience);
  ASSERT_TRUE(ok);
  EXPECT_EQ(ok->status, 200);

  auto client = connect();
  ASSERT_TRUE(client->send("GET /index.html HTTP/1.1\r\nHost: localhost\r\nX-Padding: " + std::string(4096, 'a') + "\r\n\r\n"));
  const auto res = read_response(*client, Clock::now() + kPatience);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 431);
  EXPECT_FALSE(res->keep_alive());
  EXPECT_NE(res->body.find("1024"), std::string::npos) << res->body;
  EXPECT_TRUE(client->read_until_closed(Clock::now() + kPatience));
}

TEST_F(HttpLimitsTest, ABodyOverTheLimitGets413OrResourceExhaustedAndTheConnectionCloses) {
  options_.max_request_bytes = 1000;
  start();
  const std::string body(2000, 'x');

  auto plain = connect();
  ASSERT_TRUE(plain->send("POST /upload HTTP/1.1\r\nHost: localhost\r\nContent-Type: text/plain\r\nContent-Length: 2000\r\n\r\n" +
                          body));
  const auto res = read_response(*plain, Clock::now() + kPatience);
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 413);
  EXPECT_FALSE(res->keep_alive());
  EXPECT_TRUE(plain->read_until_closed(Clock::now() + kPatience));

  // Chunked: no Content-Length to refuse up front; refused once over.
  auto chunked = connect();
  ASSERT_TRUE(chunked->send("POST /upload HTTP/1.1\r\nHost: localhost\r\nContent-Type: text/plain\r\n"
                            "Transfer-Encoding: chunked\r\n\r\n7d0\r\n" + body + "\r\n0\r\n\r\n"));
  const auto res_chunked = read_response(*chunked, Clock::now() + kPatience);
  ASSERT_TRUE(res_chunked);
  EXPECT_EQ(res_chunked->status, 413);
  EXPECT_TRUE(chunked->read_until_closed(Clock::now() + kPatience));

  // gRPC-Web: the status a gRPC-Web client understands, in the trailer frame.
  auto grpc_web = connect();
  ASSERT_TRUE(grpc_web->send("POST /filigree.v1.Filigree/ListSessions HTTP/1.1\r\nHost: localhost\r\n"
                             "Content-Type: application/grpc-web+proto\r\nX-Grpc-Web: 1\r\nContent-Length: 2000\r\n\r\n" +
                             body));
  const auto res_grpc = read_response(*grpc_web, Clock::now() + kPatience);
  ASSERT_TRUE(res_grpc);
  EXPECT_EQ(res_grpc->status, 200);
  ASSERT_GE(res_grpc->body.size(), 5u);
  EXPECT_EQ(static_cast<unsigned char>(res_grpc->body[0]), 0x80u) << "a trailer frame";
  EXPECT_NE(res_grpc->body.find("grpc-status:8"), std::string::npos) << res_grpc->body;  // RESOURCE_EXHAUSTED
  EXPECT_FALSE(res_grpc->keep_alive());
  EXPECT_TRUE(grpc_web->read_until_closed(Clock::now() + kPatience));
}

// ------------------------------------------------------------ connections

TEST_F(HttpLimitsTest, ConnectionsOverTheCapGet503AndASlotFreesWhenOneCloses) {
  options_.max_connections = 2;
  start();
  auto a = connect();
  auto b = connect();
  expect_index(*a);  // both registered: each has been served
  expect_index(*b);

  auto refused = connect();
  ASSERT_TRUE(refused->read_until_closed(Clock::now() + kPatience));
  const auto busy = test::take_response(refused->received());
  ASSERT_TRUE(busy);
  EXPECT_EQ(busy->status, 503);
  EXPECT_EQ(busy->headers.count("retry-after") ? busy->headers.at("retry-after") : "", "1");
  EXPECT_FALSE(busy->keep_alive());
  expect_index(*b);  // the connections held are not disturbed

  // A closes; the server notices (EOF) and frees its slot. When exactly is
  // the server's business: try again until served, within the deadline.
  a->close();
  const Clock::time_point deadline = Clock::now() + kPatience;
  std::optional<test::HttpResponse> res;
  std::unique_ptr<RawSocket> c;
  while (Clock::now() < deadline) {
    c = connect();
    if (!c->send(get())) continue;
    res = read_response(*c, deadline);
    if (res && res->status != 503) break;
    std::this_thread::sleep_for(10ms);  // between attempts of a retry loop, not a synchronisation
  }
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_EQ(res->body, kIndex);
}

}  // namespace
}  // namespace filigree
