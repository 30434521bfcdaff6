// TLS to Redis: RedisClient and filigree-server against a redis-server started
// here with only a TLS port (--port 0). Its CA, server and client certificates
// are made at run time with the openssl command into a temporary directory
// (never in the repository), with a second CA that signed nothing of Redis'.

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "filigree/client.h"
#include "server/state/redis_client.h"
#include "server/state/session_store.h"
#include "support/child_process.h"
#include "support/pki.h"
#include "support/server_process.h"
#include "support/server_run.h"
#include "support/store_errors.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using server::RedisClient;
using server::RedisCredentials;
using server::RedisTlsOptions;
using server::StoreUnavailable;

constexpr std::chrono::milliseconds kTimeout(2000);

using test::random_password;
using test::store_error;

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// Certificates for every test, made once: the CA Redis' certificate chains to,
// Redis' own (valid for 127.0.0.1 and redis.test), a client certificate from
// the same CA, and another CA with a client certificate of its own.
class Certificates {
 public:
  static const Certificates& get() {
    static const Certificates certificates;
    return certificates;
  }
  fs::path file(const std::string& name) const { return dir_ / name; }

 private:
  Certificates() {
    char tmpl[] = "/tmp/filigree-redis-tls-certs-XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
    dir_ = tmpl;
    test::Pki pki(dir_);
    pki.ca("ca");
    pki.ca("other-ca");
    pki.issue("redis", "ca", "subjectAltName=IP:127.0.0.1,DNS:redis.test\nextendedKeyUsage=serverAuth");
    pki.issue("client", "ca", test::kClient);
    pki.issue("stranger", "other-ca", test::kClient);
  }
  ~Certificates() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  fs::path dir_;
};

struct RedisConfig {
  bool client_certificates = false;  // tls-auth-clients yes
  bool password = false;             // requirepass
  bool plaintext_port = false;       // a plaintext port besides the TLS one
};

class RedisTls : public ::testing::Test {
 protected:
  RedisTls() : certs_(Certificates::get()) {
    char tmpl[] = "/tmp/filigree-redis-tls-XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
    dir_ = tmpl;
  }
  ~RedisTls() override {
    redis_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // Starts redis-server with a TLS port only (unless `config.plaintext_port`).
  void start_redis(const RedisConfig& config) {
    const int tls_port = test::free_port();
    address_ = "127.0.0.1:" + std::to_string(tls_port);
    std::string conf = "bind 127.0.0.1\nsave \"\"\nappendonly no\ndir " + dir_.string() + "\ntls-port " +
                       std::to_string(tls_port) + "\ntls-cert-file " + certs_.file("redis.pem").string() +
                       "\ntls-key-file " + certs_.file("redis.key").string() + "\ntls-ca-cert-file " +
                       certs_.file("ca.pem").string() + "\ntls-auth-clients " +
                       (config.client_certificates ? "yes" : "no") + "\n";
    if (config.plaintext_port) {
      const int port = test::free_port();
      plain_address_ = "127.0.0.1:" + std::to_string(port);
      conf += "port " + std::to_string(port) + "\n";
    } else {
      conf += "port 0\n";
    }
    if (config.password) conf += "requirepass " + password_ + "\n";
    const fs::path file = dir_ / "redis.conf";
    std::ofstream(file) << conf;
    fs::permissions(file, fs::perms::owner_read | fs::perms::owner_write);  // it holds the password
    redis_ = std::make_unique<test::ChildProcess>(std::vector<std::string>{"redis-server", file.string()},
                                                  (dir_ / "redis.log").string());
    redis_->wait_for_port(tls_port, 20);
  }

  // TLS trusting `ca` (a file of the certificates' directory; empty: the system store).
  RedisTlsOptions tls(const std::string& ca = "ca.pem") const {
    RedisTlsOptions options;
    options.enabled = true;
    if (!ca.empty()) options.ca_file = certs_.file(ca).string();
    return options;
  }
  RedisTlsOptions tls_with_client(const std::string& name) const {
    RedisTlsOptions options = tls();
    options.cert_file = certs_.file(name + ".pem").string();
    options.key_file = certs_.file(name + ".key").string();
    return options;
  }
  std::string password_file() const {
    const fs::path file = dir_ / "password";
    std::ofstream(file) << password_ << "\n";
    fs::permissions(file, fs::perms::owner_read | fs::perms::owner_write);
    return file.string();
  }

  const Certificates& certs_;
  fs::path dir_;
  std::string address_, plain_address_;
  const std::string password_ = random_password();
  std::unique_ptr<test::ChildProcess> redis_;
};

TEST_F(RedisTls, CommandsAndEvalWorkOverTls) {
  start_redis({});
  RedisClient redis(address_, kTimeout, {}, tls());
  redis.command({"SET", "k", "v"});
  EXPECT_EQ(redis.command({"GET", "k"}).str, "v");
  const auto sum = redis.eval("return tonumber(ARGV[1]) + redis.call('STRLEN', KEYS[1])", {"k"}, {"41"});
  EXPECT_EQ(sum.integer, 42);
  // A value of many TLS records, NULs included, both ways (hierarchies are megabytes).
  std::string big(3 << 20, '\0');
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = static_cast<char>(i * 131 % 251);
  redis.command({"SET", "big", big});
  EXPECT_EQ(redis.command({"GET", "big"}).str, big);
  // The certificate's DNS name, verified instead of the address' host.
  RedisTlsOptions by_name = tls();
  by_name.server_name = "redis.test";
  RedisClient named(address_, kTimeout, {}, by_name);
  EXPECT_EQ(named.command({"GET", "k"}).str, "v");
}

TEST_F(RedisTls, ABrokenConnectionIsReplacedByANewTlsConnection) {
  start_redis({});
  RedisClient client(address_, kTimeout, {}, tls()), admin(address_, kTimeout, {}, tls());
  admin.command({"CLIENT", "KILL", "TYPE", "normal"});  // every other client's connection
  EXPECT_THROW(client.command({"SET", "k", "before"}), StoreUnavailable);
  client.command({"SET", "k", "after"});
  EXPECT_EQ(admin.command({"GET", "k"}).str, "after");
}

TEST_F(RedisTls, AnUntrustedCertificateFailsSayingItCannotBeVerified) {
  start_redis({});
  const std::string wrong_ca = store_error([&] { RedisClient c(address_, kTimeout, {}, tls("other-ca.pem")); });
  EXPECT_TRUE(contains(wrong_ca, "cannot verify the TLS certificate of Redis at " + address_)) << wrong_ca;
  // Redis sends its CA along (OpenSSL completes the chain it serves), so the chain ends in an unknown root.
  EXPECT_TRUE(contains(wrong_ca, "self-signed certificate in certificate chain") ||
              contains(wrong_ca, "unable to get local issuer certificate"))
      << wrong_ca;
  EXPECT_TRUE(contains(wrong_ca, "other-ca.pem")) << wrong_ca;
  // Without a CA file, the system store: it does not know this test's CA either.
  const std::string system = store_error([&] { RedisClient c(address_, kTimeout, {}, tls("")); });
  EXPECT_TRUE(contains(system, "cannot verify the TLS certificate")) << system;
  EXPECT_TRUE(contains(system, "the system CA store")) << system;
}

TEST_F(RedisTls, ACertificateForAnotherNameFailsVerification) {
  start_redis({});
  RedisTlsOptions other = tls();
  other.server_name = "other.test";
  const std::string message = store_error([&] { RedisClient c(address_, kTimeout, {}, other); });
  EXPECT_TRUE(contains(message, "cannot verify the TLS certificate")) << message;
  EXPECT_TRUE(contains(message, "hostname mismatch")) << message;
  EXPECT_TRUE(contains(message, "'other.test'")) << message;
}

TEST_F(RedisTls, ARedisThatWantsClientCertificatesRefusesNoneAndAcceptsItsOwn) {
  start_redis({.client_certificates = true});
  const std::string none = store_error([&] { RedisClient c(address_, kTimeout, {}, tls()); });
  EXPECT_TRUE(contains(none, "refused the TLS connection")) << none;
  EXPECT_TRUE(contains(none, "--redis-tls-cert")) << none;
  // A certificate from a CA Redis does not trust is refused too.
  const std::string stranger = store_error([&] { RedisClient c(address_, kTimeout, {}, tls_with_client("stranger")); });
  EXPECT_TRUE(contains(stranger, "refused the TLS connection")) << stranger;
  EXPECT_TRUE(contains(stranger, "stranger.pem")) << stranger;
  EXPECT_FALSE(contains(stranger, "BEGIN")) << stranger;  // never a key's or certificate's contents

  RedisClient redis(address_, kTimeout, {}, tls_with_client("client"));
  redis.command({"SET", "k", "v"});
  EXPECT_EQ(redis.command({"GET", "k"}).str, "v");
}

TEST_F(RedisTls, UnusableClientCertificateFilesFailAtStartNamingTheFile) {
  start_redis({});
  RedisTlsOptions mismatched = tls_with_client("client");
  mismatched.key_file = certs_.file("stranger.key").string();
  const std::string message = store_error([&] { RedisClient c(address_, kTimeout, {}, mismatched); });
  EXPECT_TRUE(contains(message, "stranger.key")) << message;
  EXPECT_TRUE(contains(message, "mismatch")) << message;
  RedisTlsOptions missing = tls();
  missing.ca_file = (dir_ / "absent.pem").string();
  const std::string absent = store_error([&] { RedisClient c(address_, kTimeout, {}, missing); });
  EXPECT_TRUE(contains(absent, "cannot load the CA file " + missing.ca_file)) << absent;
}

TEST_F(RedisTls, TlsAndAPasswordTogether) {
  start_redis({.client_certificates = true, .password = true});
  RedisClient redis(address_, kTimeout, {"", password_}, tls_with_client("client"));
  redis.command({"SET", "k", "v"});
  EXPECT_EQ(redis.command({"GET", "k"}).str, "v");
  const std::string none = store_error([&] { RedisClient c(address_, kTimeout, {}, tls_with_client("client")); });
  EXPECT_TRUE(contains(none, "needs authentication and no password was given")) << none;
  const std::string wrong = random_password();
  const std::string refused = store_error([&] {
    RedisClient c(address_, kTimeout, {"", wrong}, tls_with_client("client"));
  });
  EXPECT_TRUE(contains(refused, "refused authentication")) << refused;
  EXPECT_FALSE(contains(refused, wrong)) << refused;
  EXPECT_FALSE(contains(refused, password_)) << refused;
}

TEST_F(RedisTls, AClientOnTheWrongTransportFailsCleanlyAndQuickly) {
  start_redis({.plaintext_port = true});
  // Plaintext to the TLS port: Redis drops the connection, and the message says what to do.
  auto start = std::chrono::steady_clock::now();
  const std::string plain = store_error([&] { RedisClient c(address_, kTimeout); });
  EXPECT_LT(std::chrono::steady_clock::now() - start, kTimeout);
  EXPECT_TRUE(contains(plain, "Redis at " + address_)) << plain;
  EXPECT_TRUE(contains(plain, "--redis-tls")) << plain;
  // TLS to the plaintext port: Redis takes the ClientHello for the start of a
  // command and waits for its end; the handshake gives up after the timeout.
  const std::chrono::milliseconds timeout(500);
  start = std::chrono::steady_clock::now();
  const std::string tls_to_plain = store_error([&] { RedisClient c(plain_address_, timeout, {}, tls()); });
  EXPECT_LT(std::chrono::steady_clock::now() - start, timeout * 5);
  EXPECT_TRUE(contains(tls_to_plain, "Redis at " + plain_address_)) << tls_to_plain;
  EXPECT_TRUE(contains(tls_to_plain, "TLS handshake")) << tls_to_plain;
}

// A peer that accepts the connection and never says a word: the handshake
// waits for its ServerHello, at most the timeout.
TEST_F(RedisTls, ASilentPeerFailsTheHandshakeAfterTheTimeout) {
  const int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof a;
  ASSERT_EQ(bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  ASSERT_EQ(listen(fd, 4), 0);  // the kernel completes connections; nobody reads them
  ASSERT_EQ(getsockname(fd, reinterpret_cast<sockaddr*>(&a), &size), 0);
  const std::string silent = "127.0.0.1:" + std::to_string(ntohs(a.sin_port));
  const std::chrono::milliseconds timeout(300);
  const auto start = std::chrono::steady_clock::now();
  const std::string message = store_error([&] { RedisClient c(silent, timeout, {}, tls()); });
  const auto took = std::chrono::steady_clock::now() - start;
  close(fd);
  EXPECT_TRUE(contains(message, "did not answer within 300 ms")) << message;
  EXPECT_GE(took, timeout);
  EXPECT_LT(took, timeout * 5);
}

TEST_F(RedisTls, ServerOverTlsWithAClientCertificateAndPasswordKeepsSessionsInRedis) {
  start_redis({.client_certificates = true, .password = true});
  const std::vector<std::string> args{"--redis",
                                      address_,
                                      "--redis-tls",
                                      "--redis-tls-ca",
                                      certs_.file("ca.pem").string(),
                                      "--redis-tls-cert",
                                      certs_.file("client.pem").string(),
                                      "--redis-tls-key",
                                      certs_.file("client.key").string(),
                                      "--redis-password-file",
                                      password_file()};
  std::vector<std::string> server_args = args;
  server_args.insert(server_args.end(), {"--data-dir", (dir_ / "data").string()});
  test::ServerProcess server(FILIGREE_SERVER_BINARY, server_args);
  const SessionHandle s =
      Client(server.address())
          .create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", {}, "tls");
  RedisClient redis(address_, kTimeout, {"", password_}, tls_with_client("client"));
  EXPECT_EQ(redis.command({"EXISTS", "filigree:session:" + s.session_id}).integer, 1);
  EXPECT_EQ(server.terminate(), 0);

  // Its log says the transport, never the password.
  const test::ServerRun run = test::run_server(FILIGREE_SERVER_BINARY, args);
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_EQ(run.status, 0) << run.output;
  EXPECT_TRUE(contains(run.output, "redis_transport=mutual-tls")) << run.output;
  EXPECT_TRUE(contains(run.output, "redis_auth=password")) << run.output;
  EXPECT_FALSE(contains(run.output, password_)) << run.output;
}

// As when Redis cannot be reached: the server does not start, and says why.
TEST_F(RedisTls, ServerThatCannotVerifyRedisExitsSayingWhy) {
  start_redis({});
  const test::ServerRun wrong_ca =
      test::run_server(FILIGREE_SERVER_BINARY,
                       {"--redis", address_, "--redis-tls", "--redis-tls-ca", certs_.file("other-ca.pem").string()});
  EXPECT_FALSE(wrong_ca.listened);
  EXPECT_EQ(wrong_ca.status, 1) << wrong_ca.output;
  EXPECT_TRUE(contains(wrong_ca.output, "event=fatal")) << wrong_ca.output;
  EXPECT_TRUE(contains(wrong_ca.output, "cannot verify the TLS certificate")) << wrong_ca.output;

  // TLS options without --redis-tls are refused, not silently ignored.
  const test::ServerRun no_flag =
      test::run_server(FILIGREE_SERVER_BINARY, {"--redis", address_, "--redis-tls-ca", certs_.file("ca.pem").string()});
  EXPECT_FALSE(no_flag.listened);
  EXPECT_NE(no_flag.status, 0) << no_flag.output;
  // Refused while reading the options, not by a plaintext connection failing later.
  EXPECT_TRUE(contains(no_flag.output, "--redis-tls-ca requires --redis-tls")) << no_flag.output;
  EXPECT_FALSE(contains(no_flag.output, "event=fatal")) << no_flag.output;
  // A certificate without its key.
  const test::ServerRun half = test::run_server(
      FILIGREE_SERVER_BINARY, {"--redis", address_, "--redis-tls", "--redis-tls-ca", certs_.file("ca.pem").string(),
                               "--redis-tls-cert", certs_.file("client.pem").string()});
  EXPECT_EQ(half.status, 1) << half.output;
  EXPECT_TRUE(contains(half.output, "--redis-tls-cert and --redis-tls-key go together")) << half.output;
}

}  // namespace
}  // namespace filigree
