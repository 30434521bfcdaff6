// The gRPC port's certificate and key are checked before they are put in
// force (server/tls_pair_check.h, server/verified_tls_files.h):
//  - at start, an empty, garbage, key-less, expired, mismatched, weak (RSA
//    1024) or SHA-1-signed pair refuses the start with a message saying
//    which file and what is wrong, and no key material;
//  - on re-read, files that become any of those keep the good pair serving
//    new handshakes, with one warning per change saying why, and the next
//    good pair is picked up; a client CA bundle likewise.
// filigree-server runs as a child process; certificates are made by the
// openssl CLI at run time.

#include <chrono>
#include <csignal>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "server/tls_pair_check.h"
#include "support/pki.h"
#include "support/server_run.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using test::CertOptions;
using test::kLoopbackServer;
using test::Pki;

constexpr long kFirstSerial = 5001, kSecondSerial = 5002;

std::string file_text(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

// Replaces `to` by a copy of `from` at once (a rename), as a deployment would.
void install(const fs::path& from, const fs::path& to) {
  const fs::path tmp = to.string() + ".new";
  fs::copy_file(from, tmp, fs::copy_options::overwrite_existing);
  fs::rename(tmp, to);
}

// Overwrites `p` in place (same inode), as `cat > file` or `cp` does.
void overwrite(const fs::path& p, const std::string& bytes) {
  std::ofstream(p, std::ios::binary | std::ios::trunc) << bytes;
}

std::size_t count(const std::string& text, const std::string& part) {
  std::size_t n = 0;
  for (auto at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) ++n;
  return n;
}

// Base64 lines of the key's PEM body: none of them may appear in any output.
std::vector<std::string> key_lines(const fs::path& key) {
  std::vector<std::string> out;
  std::istringstream in(file_text(key));
  for (std::string line; std::getline(in, line);)
    if (line.size() > 16 && line.find("-----") == std::string::npos) out.push_back(line);
  return out;
}

// filigree-server with TLS, its stdout and stderr in a file that the test
// reads as it grows. Killed at the end.
class LoggedServer {
 public:
  LoggedServer(const std::vector<std::string>& args, const fs::path& log) : log_(log) {
    std::vector<std::string> all = {FILIGREE_SERVER_BINARY, "--listen", "127.0.0.1:0", "--log-level", "info"};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (auto& a : all) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) throw std::runtime_error("cannot open the server log");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(fd, STDOUT_FILENO);
      ::dup2(fd, STDERR_FILENO);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(fd);
    const std::string prefix = "listening on ";
    if (!wait_for([&] { return text().find(prefix) != std::string::npos || exited(); }, 30s) || exited())
      throw std::runtime_error("filigree-server did not start:\n" + text());
    const std::string all_text = text();
    const auto at = all_text.find(prefix) + prefix.size();
    address_ = all_text.substr(at, all_text.find('\n', at) - at);
  }
  ~LoggedServer() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }

  const std::string& address() const { return address_; }
  std::string text() const { return file_text(log_); }
  void signal(int s) const { ::kill(pid_, s); }
  bool exited() {
    if (pid_ <= 0) return true;
    int status = 0;
    if (::waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      return true;
    }
    return false;
  }

  // Polls `done` until it holds or `limit` passes.
  template <class Done>
  static bool wait_for(Done done, std::chrono::milliseconds limit) {
    const auto deadline = std::chrono::steady_clock::now() + limit;
    while (!done()) {
      if (std::chrono::steady_clock::now() > deadline) return false;
      std::this_thread::sleep_for(20ms);  // a poll interval, not a synchronisation
    }
    return true;
  }

 private:
  fs::path log_;
  pid_t pid_ = -1;
  std::string address_;
};

// The serial number of the certificate the server presents to a new
// connection (a new handshake: a channel of its own), after a ListSessions
// call that succeeded; -1 when the handshake or call fails.
// With `client`: presents NAME.pem / NAME.key of that path stem (mutual TLS).
long served_serial(const std::string& address, const fs::path& ca, const std::optional<fs::path>& client = {}) {
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = file_text(ca);
  if (client) {
    ssl.pem_cert_chain = file_text(client->string() + ".pem");
    ssl.pem_private_key = file_text(client->string() + ".key");
  }
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // never reuse another channel's connection
  args.SetSslTargetNameOverride("localhost");
  auto stub = v1::Filigree::NewStub(grpc::CreateCustomChannel(address, grpc::SslCredentials(ssl), args));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + 10s);
  v1::ListSessionsResponse out;
  if (!stub->ListSessions(&ctx, v1::ListSessionsRequest(), &out).ok()) return -1;
  const auto pem = ctx.auth_context()->FindPropertyValues("x509_pem_cert");
  if (pem.empty()) return -1;
  BIO* bio = BIO_new_mem_buf(pem.front().data(), static_cast<int>(pem.front().size()));
  X509* cert = PEM_read_bio_X509(bio, nullptr, nullptr, nullptr);
  BIO_free(bio);
  if (!cert) return -1;
  const long serial = ASN1_INTEGER_get(X509_get_serialNumber(cert));
  X509_free(cert);
  return serial;
}

class TlsReload : public ::testing::Test {
 protected:
  void SetUp() override {
    scratch_ = fs::path(::testing::TempDir()) / ("filigree_tls_reload_" + std::to_string(::getpid()) + "_" +
                                                 ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(scratch_);
    fs::create_directories(scratch_ / "live");
    pki_.emplace(scratch_ / "pki");
    pki_->ca("ca");
    pki_->issue("server-1", "ca", kLoopbackServer, kFirstSerial);
    pki_->issue("server-2", "ca", kLoopbackServer, kSecondSerial);
    // Same key as server-1, so that one file alone makes the pair bad.
    pki_->reissue("expired-1", "server-1", "ca", kLoopbackServer, 5003, CertOptions{"ec", "", -1});
    pki_->reissue("sha1-1", "server-1", "ca", kLoopbackServer, 5004, CertOptions{"ec", "sha1", 1});
    install(*pki_ / "server-1.pem", cert());
    install(*pki_ / "server-1.key", key());
  }
  void TearDown() override { fs::remove_all(scratch_); }

  fs::path cert() const { return scratch_ / "live" / "server.pem"; }
  fs::path key() const { return scratch_ / "live" / "server.key"; }
  std::vector<std::string> tls_args() const {
    return {"--tls-cert", cert().string(), "--tls-key", key().string(), "--tls-refresh", "1"};
  }

  fs::path scratch_;
  std::optional<Pki> pki_;
};

TEST_F(TlsReload, ABadPairRefusesTheStartSayingWhichFileAndWhy) {
  pki_->issue("rsa-1024", "ca", kLoopbackServer, 5005, CertOptions{"rsa:1024", "", 1});
  struct Case {
    std::string name;
    std::string cert_bytes, key_bytes;
    std::string expected;
  };
  const std::string good_cert = file_text(*pki_ / "server-1.pem"), good_key = file_text(*pki_ / "server-1.key");
  const std::vector<Case> cases = {
      {"empty certificate", "", good_key, "--tls-cert " + cert().string() + " is empty"},
      {"empty key", good_cert, "", "--tls-key " + key().string() + " is empty"},
      {"garbage certificate", "-----BEGIN CERTIFICATE-----\nbm90IGEgY2VydGlmaWNhdGU=\n-----END CERTIFICATE-----\n", good_key,
       "--tls-cert " + cert().string() + ": holds a CERTIFICATE block that does not parse"},
      {"a certificate where the key should be", good_cert, good_cert,
       "--tls-key " + key().string() + ": holds no private key"},
      {"expired", file_text(*pki_ / "expired-1.pem"), good_key, "expired on"},
      {"mismatched key", good_cert, file_text(*pki_ / "server-2.key"), "is not the key of the certificate /CN=server-1"},
      {"RSA 1024", file_text(*pki_ / "rsa-1024.pem"), file_text(*pki_ / "rsa-1024.key"), "has a weak key (RSA 1024 bits)"},
      {"SHA-1 signature", file_text(*pki_ / "sha1-1.pem"), good_key, "is signed with SHA1"},
  };
  std::vector<std::string> secrets = key_lines(*pki_ / "server-1.key");
  for (const auto& line : key_lines(*pki_ / "rsa-1024.key")) secrets.push_back(line);
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    overwrite(cert(), c.cert_bytes);
    overwrite(key(), c.key_bytes);
    const test::ServerRun run = test::run_server(FILIGREE_SERVER_BINARY, tls_args());
    EXPECT_FALSE(run.listened) << run.output;
    EXPECT_EQ(run.status, 1) << run.output;
    EXPECT_NE(run.output.find(c.expected), std::string::npos) << run.output;
    EXPECT_EQ(run.output.find("KEY-----"), std::string::npos) << run.output;
    for (const auto& line : secrets) EXPECT_EQ(run.output.find(line), std::string::npos) << "key material in the output";
  }
  // And a good pair starts.
  install(*pki_ / "server-1.pem", cert());
  install(*pki_ / "server-1.key", key());
  const test::ServerRun good = test::run_server(FILIGREE_SERVER_BINARY, tls_args());
  EXPECT_TRUE(good.listened) << good.output;
  EXPECT_NE(good.output.find("event=tls_certificate reason=start subject=\"/CN=server-1\""), std::string::npos)
      << good.output;
}

TEST_F(TlsReload, BadReplacementsKeepTheGoodPairServingAndAreLoggedOnceEach) {
  LoggedServer server(tls_args(), scratch_ / "server.log");
  const fs::path ca = *pki_ / "ca.pem";
  ASSERT_EQ(served_serial(server.address(), ca), kFirstSerial);

  struct Case {
    std::string name;
    std::function<void()> spoil;  // one file made bad
    std::string reason;           // in the warning
  };
  const std::vector<Case> cases = {
      // The crash of issue 35: a renewal that truncates before it writes.
      {"empty key", [&] { overwrite(key(), ""); }, "--tls-key " + key().string() + " is empty"},
      {"empty certificate", [&] { overwrite(cert(), ""); }, "--tls-cert " + cert().string() + " is empty"},
      {"garbage certificate", [&] { overwrite(cert(), "-----BEGIN CERTIFICATE-----\nZ2FyYmFnZQ==\n-----END CERTIFICATE-----\n"); },
       "does not parse"},
      {"a certificate where the key should be", [&] { install(*pki_ / "server-1.pem", key()); }, "holds no private key"},
      {"expired", [&] { install(*pki_ / "expired-1.pem", cert()); }, "expired on"},
      {"mismatched key", [&] { install(*pki_ / "server-2.key", key()); }, "is not the key of the certificate /CN=server-1"},
      {"SHA-1 signature", [&] { install(*pki_ / "sha1-1.pem", cert()); }, "is signed with SHA1"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::size_t restored_before = count(server.text(), "event=tls_certificate reason=files_changed");
    c.spoil();
    ASSERT_TRUE(LoggedServer::wait_for([&] { return server.text().find(c.reason) != std::string::npos; }, 20s))
        << server.text();
    EXPECT_NE(server.text().find("level=warning event=tls_certificate_rejected"), std::string::npos);
    // New handshakes still get the good certificate, for several refresh
    // periods (the file stays bad meanwhile): one warning, not one per look.
    const auto until = std::chrono::steady_clock::now() + 2500ms;
    do {
      ASSERT_EQ(served_serial(server.address(), ca), kFirstSerial) << server.text();
    } while (std::chrono::steady_clock::now() < until);
    EXPECT_EQ(count(server.text(), c.reason), 1u) << server.text();
    EXPECT_FALSE(server.exited()) << server.text();
    // Repaired: the same good pair again.
    install(*pki_ / "server-1.pem", cert());
    install(*pki_ / "server-1.key", key());
    ASSERT_TRUE(LoggedServer::wait_for(
        [&] { return count(server.text(), "event=tls_certificate reason=files_changed") > restored_before; }, 20s))
        << server.text();
  }

  // A good new pair is picked up by itself.
  install(*pki_ / "server-2.key", key());
  install(*pki_ / "server-2.pem", cert());
  EXPECT_TRUE(LoggedServer::wait_for([&] { return served_serial(server.address(), ca) == kSecondSerial; }, 20s))
      << server.text();
  EXPECT_NE(server.text().find("subject=\"/CN=server-2\""), std::string::npos);
  const std::string log = server.text();
  EXPECT_EQ(log.find("KEY-----"), std::string::npos) << log;
  for (const auto& line : key_lines(*pki_ / "server-1.key")) EXPECT_EQ(log.find(line), std::string::npos);
}

TEST_F(TlsReload, SighupLooksAtTheFilesAtOnce) {
  std::vector<std::string> args = tls_args();
  args.back() = "3600";  // the timer would not look during this test
  LoggedServer server(args, scratch_ / "server.log");
  const fs::path ca = *pki_ / "ca.pem";
  ASSERT_EQ(served_serial(server.address(), ca), kFirstSerial);
  overwrite(key(), "");
  server.signal(SIGHUP);
  ASSERT_TRUE(LoggedServer::wait_for([&] { return server.text().find("is empty") != std::string::npos; }, 20s))
      << server.text();
  EXPECT_EQ(served_serial(server.address(), ca), kFirstSerial);
  install(*pki_ / "server-2.key", key());
  install(*pki_ / "server-2.pem", cert());
  server.signal(SIGHUP);
  EXPECT_TRUE(LoggedServer::wait_for([&] { return served_serial(server.address(), ca) == kSecondSerial; }, 20s))
      << server.text();
}

TEST_F(TlsReload, ABadClientCaBundleKeepsTheOneInForce) {
  pki_->ca("clients-1");
  pki_->ca("clients-2");
  pki_->issue("alice", "clients-1", test::kClient, 7001);
  pki_->issue("bob", "clients-2", test::kClient, 7002);
  const fs::path bundle = scratch_ / "live" / "clients.pem";
  install(*pki_ / "clients-1.pem", bundle);
  std::vector<std::string> args = tls_args();
  args.insert(args.end(), {"--tls-client-ca", bundle.string()});
  LoggedServer server(args, scratch_ / "server.log");
  const fs::path ca = *pki_ / "ca.pem";
  ASSERT_EQ(served_serial(server.address(), ca, *pki_ / "alice"), kFirstSerial) << server.text();
  EXPECT_EQ(served_serial(server.address(), ca, *pki_ / "bob"), -1) << "a client of a CA not in the bundle";

  // Emptied (a renewal that truncates first): warned about, the bundle in force stays.
  overwrite(bundle, "");
  ASSERT_TRUE(LoggedServer::wait_for(
      [&] { return server.text().find("--tls-client-ca " + bundle.string() + " is empty") != std::string::npos; }, 20s))
      << server.text();
  EXPECT_NE(server.text().find("level=warning event=tls_ca_bundle_rejected"), std::string::npos);
  EXPECT_EQ(served_serial(server.address(), ca, *pki_ / "alice"), kFirstSerial) << server.text();

  // A good new bundle is taken.
  overwrite(bundle, file_text(*pki_ / "clients-1.pem") + file_text(*pki_ / "clients-2.pem"));
  EXPECT_TRUE(LoggedServer::wait_for([&] { return served_serial(server.address(), ca, *pki_ / "bob") == kFirstSerial; }, 20s))
      << server.text();
}

// ------------------------------------------------------------ the check itself

class TlsPairCheck : public TlsReload {};

TEST_F(TlsPairCheck, AcceptsAGoodPairAndSaysWhatItIs) {
  const auto summary = server::check_tls_pair(file_text(*pki_ / "server-1.pem"), file_text(*pki_ / "server-1.key"));
  EXPECT_EQ(summary.subject, "/CN=server-1");
  EXPECT_EQ(summary.key, "EC 256 bits");
  EXPECT_FALSE(summary.not_after.empty());
}

TEST_F(TlsPairCheck, ACertificateNotYetValidIsRefused) {
  const std::time_t yesterday = std::time(nullptr) - 2 * 24 * 3600;
  try {
    server::check_tls_pair(file_text(*pki_ / "server-1.pem"), file_text(*pki_ / "server-1.key"), yesterday);
    FAIL() << "a certificate not valid yet was accepted";
  } catch (const server::TlsPairError& e) {
    EXPECT_EQ(e.part(), server::TlsPairError::Part::kChain);
    EXPECT_NE(std::string(e.what()).find("is not valid before"), std::string::npos) << e.what();
  }
}

TEST_F(TlsPairCheck, AnExpiredIntermediateIsRefused) {
  pki_->issue("expired-intermediate", "ca", "basicConstraints=critical,CA:TRUE", 5010, CertOptions{"ec", "", -1});
  // The chain: the leaf, then an expired intermediate sent with it.
  const std::string chain = file_text(*pki_ / "server-1.pem") + file_text(*pki_ / "expired-intermediate.pem");
  try {
    server::check_tls_pair(chain, file_text(*pki_ / "server-1.key"));
    FAIL() << "an expired certificate in the chain was accepted";
  } catch (const server::TlsPairError& e) {
    EXPECT_NE(std::string(e.what()).find("certificate 2 of the chain"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("expired on"), std::string::npos) << e.what();
  }
}

TEST_F(TlsPairCheck, AnEncryptedKeyIsRefusedWithoutAskingForAPassphrase) {
  const std::string encrypted = "-----BEGIN ENCRYPTED PRIVATE KEY-----\nMIIB\n-----END ENCRYPTED PRIVATE KEY-----\n";
  try {
    server::check_tls_pair(file_text(*pki_ / "server-1.pem"), encrypted);
    FAIL() << "an encrypted key was accepted";
  } catch (const server::TlsPairError& e) {
    EXPECT_EQ(e.part(), server::TlsPairError::Part::kKey);
    EXPECT_NE(std::string(e.what()).find("encrypted"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace filigree
