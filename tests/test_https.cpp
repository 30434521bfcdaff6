// HTTPS on the browser port (HttpServer with HttpOptions::tls): static files,
// gRPC-Web unary and streaming calls, keep-alive and the too-large answer
// over TLS; an untrusted server certificate, a plaintext request and missing
// client certificates (mutual TLS) fail cleanly; replaced certificate files
// reach new connections (on reload_certificates() and by themselves) while
// open connections keep theirs, and bad ones (garbage, mismatched, empty,
// expired, weak, SHA-1-signed) keep the old certificate; every response
// carries HSTS, Referrer-Policy and nosniff.
//
// In-process: the HTTP server in front of a gRPC server that has only a fake
// filigree.v1.Filigree (the transport is under test, not the service). The
// certificates are made by the openssl CLI into a temporary directory.

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/ssl.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/http.hpp>
#include <boost/beast/ssl.hpp>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <openssl/ssl.h>
#include <openssl/x509.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "server/http/http_server.h"
#include "support/grpc_web_frames.h"
#include "support/https_client.h"
#include "support/pki.h"

namespace filigree {
namespace {

// The HTTPS client, the gRPC-Web frames, the PKI, and their namespace
// aliases (beast, bhttp, net, ssl, fs, tcp).
using namespace test;

// ------------------------------------------------------------ certificates

// Replaces `to` by a copy of `from` at once (a rename), as a deployment would.
void install(const fs::path& from, const fs::path& to) {
  const fs::path tmp = to.string() + ".new";
  fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
  fs::rename(tmp, to);
}

void write_file(const fs::path& p, const std::string& bytes) {
  const fs::path tmp = p.string() + ".new";
  std::ofstream(tmp, std::ios::binary) << bytes;
  fs::rename(tmp, p);
}

// ------------------------------------------------------------ the fake service

constexpr char kSessionId[] = "https-session";
constexpr int kWatchFrames = 3;

class FakeFiligree final : public v1::Filigree::Service {
  grpc::Status ListSessions(grpc::ServerContext*, const v1::ListSessionsRequest*, v1::ListSessionsResponse* out) override {
    out->add_sessions()->set_session_id(kSessionId);
    return grpc::Status::OK;
  }
  grpc::Status Watch(grpc::ServerContext*, const v1::WatchRequest*, grpc::ServerWriter<v1::Frame>* writer) override {
    for (int v = 1; v <= kWatchFrames; ++v) {
      v1::Frame frame;
      frame.set_version(v);
      if (!writer->Write(frame)) return grpc::Status::CANCELLED;
    }
    return grpc::Status::OK;
  }
};

// ------------------------------------------------------------ fixture

constexpr char kIndex[] = "<!doctype html><title>Filigree over TLS</title>";
constexpr int kFirstSerial = 4097, kSecondSerial = 4098, kThirdSerial = 4099;

class HttpsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    scratch_ = fs::path(::testing::TempDir()) /
               ("filigree_https_" + std::to_string(::getpid()) + "_" +
                ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(scratch_);
    fs::create_directories(scratch_ / "www");
    fs::create_directories(scratch_ / "live");
    std::ofstream(scratch_ / "www" / "index.html") << kIndex;
    pki_.emplace(scratch_ / "pki");
    pki_->ca("test-ca");
    pki_->ca("other-ca");
    pki_->issue("server-1", "test-ca", kLoopbackServer, kFirstSerial);
    pki_->issue("server-2", "test-ca", kLoopbackServer, kSecondSerial);
    install(*pki_ / "server-1.pem", cert_path());
    install(*pki_ / "server-1.key", key_path());

    grpc::ServerBuilder builder;
    builder.RegisterService(&service_);
    grpc_server_ = builder.BuildAndStart();
    ASSERT_TRUE(grpc_server_);
  }

  void TearDown() override {
    http_.reset();
    if (grpc_server_) grpc_server_->Shutdown();
    fs::remove_all(scratch_);
  }

  fs::path cert_path() const { return scratch_ / "live" / "server.pem"; }
  fs::path key_path() const { return scratch_ / "live" / "server.key"; }

  // refresh: how often the files are checked by themselves (3600 s: only on reload_certificates()).
  void start(std::chrono::seconds refresh = std::chrono::seconds(3600), std::string client_ca = "",
             std::size_t max_request_bytes = 4u << 20) {
    server::http::HttpOptions options;
    options.listen = "127.0.0.1:0";
    options.web_root = scratch_ / "www";
    options.grpc_web_services = {v1::Filigree::service_full_name()};
    options.max_request_bytes = max_request_bytes;
    options.threads = 2;
    options.tls = {cert_path().string(), key_path().string(), std::move(client_ca), refresh};
    http_ = std::make_unique<server::http::HttpServer>(std::move(options),
                                                       grpc_server_->InProcessChannel(grpc::ChannelArguments()));
    ASSERT_TRUE(http_->https());
    trusting_ = client_context(*pki_ / "test-ca.pem");
  }

  // A new connection trusting the test CA.
  std::unique_ptr<HttpsClient> connect() { return std::make_unique<HttpsClient>(http_->address(), *trusting_); }

  // The index page over `client`, checked.
  static void expect_index(HttpsClient& client) {
    const auto res = client.exchange(get("/index.html"));
    EXPECT_EQ(res.result_int(), 200u);
    EXPECT_EQ(res.body(), kIndex);
    EXPECT_TRUE(res.keep_alive());
  }

  fs::path scratch_;
  std::optional<Pki> pki_;
  FakeFiligree service_;
  std::unique_ptr<grpc::Server> grpc_server_;
  std::unique_ptr<server::http::HttpServer> http_;
  std::unique_ptr<ssl::context> trusting_;
};

// ------------------------------------------------------------ tests

TEST_F(HttpsTest, ServesFilesAndGrpcWebOnOneKeptAliveConnection) {
  start();
  auto client = connect();
  EXPECT_EQ(client->serial(), kFirstSerial);
  EXPECT_EQ(client->common_name(), "server-1");
  expect_index(*client);

  // The same connection: keep-alive over TLS.
  const auto res = client->exchange(grpc_web_request("ListSessions", v1::ListSessionsRequest()));
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_EQ(std::string(res[bhttp::field::content_type]), "application/grpc-web+proto");
  const Frames frames = parse_frames(res.body());
  ASSERT_TRUE(frames.well_formed);
  EXPECT_NE(frames.trailer.find("grpc-status:0"), std::string::npos) << frames.trailer;
  ASSERT_EQ(frames.messages.size(), 1u);
  v1::ListSessionsResponse list;
  ASSERT_TRUE(list.ParseFromString(frames.messages[0]));
  ASSERT_EQ(list.sessions_size(), 1);
  EXPECT_EQ(list.sessions(0).session_id(), kSessionId);

  expect_index(*client);
}

TEST_F(HttpsTest, EveryResponseSaysHstsNoReferrerAndNoSniffing) {
  start();
  auto client = connect();
  const auto check = [](const auto& res) {
    EXPECT_EQ(std::string(res["strict-transport-security"]), "max-age=31536000");
    EXPECT_EQ(std::string(res["referrer-policy"]), "no-referrer");
    EXPECT_EQ(std::string(res["x-content-type-options"]), "nosniff");
  };
  check(client->exchange(get("/index.html")));
  check(client->exchange(get("/?session=s&token=t")));
  check(client->exchange(get("/no-such-file")));
  check(client->exchange(grpc_web_request("ListSessions", v1::ListSessionsRequest())));
  v1::WatchRequest watch;
  watch.set_session_id(kSessionId);
  check(client->exchange(grpc_web_request("Watch", watch)));  // a streamed response's header
}

TEST_F(HttpsTest, StreamsAServerStreamingCallThenCloses) {
  start();
  auto client = connect();
  v1::WatchRequest watch;
  watch.set_session_id(kSessionId);
  const auto res = client->exchange(grpc_web_request("Watch", watch));
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_TRUE(res.chunked());
  EXPECT_FALSE(res.keep_alive());
  const Frames frames = parse_frames(res.body());
  ASSERT_TRUE(frames.well_formed);
  EXPECT_NE(frames.trailer.find("grpc-status:0"), std::string::npos) << frames.trailer;
  ASSERT_EQ(frames.messages.size(), std::size_t(kWatchFrames));
  for (int i = 0; i < kWatchFrames; ++i) {
    v1::Frame frame;
    ASSERT_TRUE(frame.ParseFromString(frames.messages[i]));
    EXPECT_EQ(frame.version(), std::uint64_t(i + 1));
  }
  // The server closes after a stream; the connection ends, in time.
  const beast::error_code end = client->read_end();
  EXPECT_NE(end, beast::error::timeout);
  EXPECT_TRUE(end) << "no more bytes after the stream";
}

TEST_F(HttpsTest, AnOversizedBodyGetsItsAnswerThenACleanTlsClose) {
  start(std::chrono::seconds(3600), "", /*max_request_bytes=*/1024);
  auto client = connect();
  v1::WatchRequest big;
  big.set_session_id(std::string(256 * 1024, 'x'));  // never read by the server
  const auto res = client->exchange(grpc_web_request("Watch", big));
  EXPECT_EQ(res.result_int(), 200u);
  EXPECT_FALSE(res.keep_alive());
  const Frames frames = parse_frames(res.body());
  ASSERT_TRUE(frames.well_formed);
  EXPECT_NE(frames.trailer.find("grpc-status:8"), std::string::npos) << frames.trailer;  // RESOURCE_EXHAUSTED
  // close_notify, not a bare TCP close: TLS's end of stream.
  EXPECT_EQ(client->read_end(), net::error::eof);
}

TEST_F(HttpsTest, AClientThatDoesNotTrustTheCaFailsTheHandshake) {
  start();
  auto other = client_context(*pki_ / "other-ca.pem");
  try {
    HttpsClient client(http_->address(), *other);
    FAIL() << "the handshake succeeded with a CA that did not sign the server certificate";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("certificate verify failed"), std::string::npos) << e.what();
  }
  auto nothing = client_context(std::nullopt);
  EXPECT_THROW({ HttpsClient c(http_->address(), *nothing); }, std::runtime_error);
  expect_index(*connect());
}

TEST_F(HttpsTest, APlaintextRequestIsClosedAndTheServerKeepsServing) {
  start();
  net::io_context ioc;
  beast::tcp_stream plain(ioc);
  const std::string address = http_->address();
  const auto colon = address.rfind(':');
  const auto endpoints = tcp::resolver(ioc).resolve(address.substr(0, colon), address.substr(colon + 1));
  ASSERT_FALSE(run(ioc, plain, [&](auto handler) { plain.async_connect(endpoints, handler); }));
  const std::string request = "GET /index.html HTTP/1.1\r\nHost: localhost\r\n\r\n";
  ASSERT_FALSE(run(ioc, plain, [&](auto handler) { net::async_write(plain, net::buffer(request), handler); }));
  // Read everything until the server ends the connection.
  std::string received;
  beast::error_code ec;
  for (;;) {
    char chunk[1024];
    std::size_t n = 0;
    ec = run(ioc, plain, [&](auto handler) {
      plain.async_read_some(net::buffer(chunk), [&n, handler](beast::error_code e, std::size_t got) mutable {
        n = got;
        handler(e);
      });
    });
    received.append(chunk, n);
    if (ec) break;
  }
  EXPECT_TRUE(ec == net::error::eof || ec == net::error::connection_reset) << ec.message();
  EXPECT_EQ(received.find("HTTP/"), std::string::npos) << "no plaintext HTTP answer on the HTTPS port";
  EXPECT_EQ(received.find("Filigree over TLS"), std::string::npos);

  expect_index(*connect());
}

TEST_F(HttpsTest, ReloadGivesNewConnectionsTheNewCertificateAndOpenOnesKeepWorking) {
  start();
  auto before = connect();
  EXPECT_EQ(before->serial(), kFirstSerial);
  expect_index(*before);

  install(*pki_ / "server-2.key", key_path());
  install(*pki_ / "server-2.pem", cert_path());
  // Not yet: the files are checked only every hour here.
  EXPECT_EQ(connect()->serial(), kFirstSerial);
  http_->reload_certificates();

  auto after = connect();
  EXPECT_EQ(after->serial(), kSecondSerial);
  EXPECT_EQ(after->common_name(), "server-2");
  expect_index(*after);
  // The connection opened before the reload: same TLS session, still served.
  expect_index(*before);
  EXPECT_EQ(before->serial(), kFirstSerial);
  const auto res = before->exchange(grpc_web_request("ListSessions", v1::ListSessionsRequest()));
  EXPECT_NE(parse_frames(res.body()).trailer.find("grpc-status:0"), std::string::npos);
}

TEST_F(HttpsTest, ReloadOfBadFilesThrowsWhyAndKeepsTheOldCertificate) {
  start();
  // Not PEM at all.
  write_file(cert_path(), "not a certificate\n");
  try {
    http_->reload_certificates();
    FAIL() << "a certificate file without PEM was accepted";
  } catch (const std::runtime_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("--tls-cert " + cert_path().string()), std::string::npos) << what;
    EXPECT_NE(what.find("no PEM"), std::string::npos) << what;
  }
  EXPECT_EQ(connect()->serial(), kFirstSerial);

  // A certificate with another certificate's key (half a renewal).
  install(*pki_ / "server-2.pem", cert_path());
  try {
    http_->reload_certificates();
    FAIL() << "a key that does not match the certificate was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("is not the key of the certificate"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("PRIVATE KEY"), std::string::npos) << "no key material in messages";
  }
  auto client = connect();
  EXPECT_EQ(client->serial(), kFirstSerial);
  expect_index(*client);

  // Missing.
  fs::remove(key_path());
  EXPECT_THROW(http_->reload_certificates(), std::runtime_error);
  EXPECT_EQ(connect()->serial(), kFirstSerial);

  // Completed: the renewal takes.
  install(*pki_ / "server-2.key", key_path());
  http_->reload_certificates();
  EXPECT_EQ(connect()->serial(), kSecondSerial);
}

TEST_F(HttpsTest, ExpiredWeakAndSha1PairsAreRefusedAtStartAndOnReload) {
  pki_->reissue("expired", "server-1", "test-ca", kLoopbackServer, 4100, CertOptions{"ec", "", -1});
  pki_->reissue("sha1", "server-1", "test-ca", kLoopbackServer, 4101, CertOptions{"ec", "sha1", 1});
  pki_->issue("rsa-1024", "test-ca", kLoopbackServer, 4102, CertOptions{"rsa:1024", "", 1});
  struct Case {
    const char* cert;
    const char* key;
    const char* reason;
  };
  const Case cases[] = {{"expired.pem", "server-1.key", "expired on"},
                        {"sha1.pem", "server-1.key", "is signed with SHA1"},
                        {"rsa-1024.pem", "rsa-1024.key", "has a weak key (RSA 1024 bits)"}};
  const server::http::HttpsFiles files{cert_path().string(), key_path().string(), "", std::chrono::seconds(5)};
  // At start: no context is made from them.
  for (const Case& c : cases) {
    SCOPED_TRACE(c.cert);
    install(*pki_ / c.cert, cert_path());
    install(*pki_ / c.key, key_path());
    try {
      server::http::make_https_context(files);
      ADD_FAILURE() << "accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(c.reason), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("--tls-cert " + cert_path().string()), std::string::npos) << e.what();
    }
  }
  // On reload: the good certificate stays.
  install(*pki_ / "server-1.pem", cert_path());
  install(*pki_ / "server-1.key", key_path());
  start();
  for (const Case& c : cases) {
    SCOPED_TRACE(c.cert);
    install(*pki_ / c.cert, cert_path());
    install(*pki_ / c.key, key_path());
    EXPECT_THROW(http_->reload_certificates(), std::runtime_error);
    auto client = connect();
    EXPECT_EQ(client->serial(), kFirstSerial);
    expect_index(*client);
  }
  // An empty key (a renewal that truncates first): refused too, saying so.
  install(*pki_ / "server-1.pem", cert_path());
  write_file(key_path(), "");
  try {
    http_->reload_certificates();
    FAIL() << "an empty key was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--tls-key " + key_path().string() + " is empty"), std::string::npos) << e.what();
  }
  EXPECT_EQ(connect()->serial(), kFirstSerial);
}

TEST_F(HttpsTest, ReplacedFilesArePickedUpByThemselvesAndBadOnesAreNot) {
  start(std::chrono::seconds(0));  // check at every new connection
  EXPECT_EQ(connect()->serial(), kFirstSerial);
  auto open = connect();

  install(*pki_ / "server-2.key", key_path());
  install(*pki_ / "server-2.pem", cert_path());
  EXPECT_EQ(connect()->serial(), kSecondSerial);

  // A bad replacement: logged, the certificate in force stays.
  write_file(key_path(), "-----BEGIN PRIVATE KEY-----\ngarbage\n-----END PRIVATE KEY-----\n");
  auto client = connect();
  EXPECT_EQ(client->serial(), kSecondSerial);
  expect_index(*client);

  pki_->issue("server-3", "test-ca", kLoopbackServer, kThirdSerial);
  install(*pki_ / "server-3.key", key_path());
  install(*pki_ / "server-3.pem", cert_path());
  EXPECT_EQ(connect()->serial(), kThirdSerial);
  expect_index(*open);
  EXPECT_EQ(open->serial(), kFirstSerial);
}

TEST_F(HttpsTest, MutualTlsRequiresAClientCertificateOfTheClientCa) {
  pki_->ca("client-ca");
  pki_->issue("browser", "client-ca", kClient, 7);
  pki_->issue("stranger", "other-ca", kClient, 8);
  start(std::chrono::seconds(3600), (*pki_ / "client-ca.pem").string());

  auto with_cert = client_context(*pki_ / "test-ca.pem", *pki_ / "browser.pem", *pki_ / "browser.key");
  HttpsClient client(http_->address(), *with_cert);
  expect_index(client);
  const auto res = client.exchange(grpc_web_request("ListSessions", v1::ListSessionsRequest()));
  EXPECT_NE(parse_frames(res.body()).trailer.find("grpc-status:0"), std::string::npos);

  // TLS 1.3: the server checks the client certificate after the client's
  // handshake ends, so the refusal may arrive only at the first exchange.
  const auto refused = [&](ssl::context& ctx) {
    try {
      HttpsClient c(http_->address(), ctx);
      c.exchange(get("/index.html"));
      return false;
    } catch (const std::runtime_error&) {
      return true;
    }
  };
  EXPECT_TRUE(refused(*trusting_)) << "no client certificate";
  auto stranger = client_context(*pki_ / "test-ca.pem", *pki_ / "stranger.pem", *pki_ / "stranger.key");
  EXPECT_TRUE(refused(*stranger)) << "a client certificate of another CA";
  HttpsClient again(http_->address(), *with_cert);
  expect_index(again);
}

TEST(HttpsContext, BadFilesAtStartNameTheFile) {
  server::http::HttpsFiles files{"/nonexistent/server.pem", "/nonexistent/server.key", "", std::chrono::seconds(5)};
  try {
    server::http::make_https_context(files);
    FAIL() << "missing files were accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--tls-cert /nonexistent/server.pem cannot be read"), std::string::npos) << e.what();
  }
  files.key.clear();
  EXPECT_THROW(server::http::make_https_context(files), std::runtime_error);
}

}  // namespace
}  // namespace filigree
