// Replicas that serve TLS (mutual TLS included) forward a browser's call to
// the replica that serves its session over TLS too: the other replica
// verified against --peer-ca and its advertised address, this one presenting
// its own certificate. On loopback: Redis and two filigree-server replicas,
// certificates made at run time with the openssl command.

#include <gtest/gtest.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/create_channel.h>
#include <grpcpp/security/credentials.h>
#include <grpcpp/support/channel_arguments.h>

#include "filigree/client.h"
#include "support/child_process.h"
#include "support/https_client.h"
#include "support/pki.h"
#include "support/server_process.h"
#include "support/server_run.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;

// Replicas both serve and call: one certificate for both ends.
constexpr char kReplicaExtensions[] = "subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth,clientAuth";

std::string read_file(const fs::path& p) { return test::file_bytes(p.string()); }

class ClusterTls : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/filigree-cluster-tls-XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    pki_ = std::make_unique<test::Pki>(dir_ / "pki");
    pki_->ca("ca");
    pki_->ca("other-ca");
    pki_->issue("replica-1", "ca", kReplicaExtensions);
    pki_->issue("replica-2", "ca", kReplicaExtensions);
    pki_->issue("engine", "ca", test::kClient);
    // Signed by the right CA, for another name than the address it is served at.
    pki_->issue("misnamed", "ca", "subjectAltName=DNS:elsewhere.test\nextendedKeyUsage=serverAuth,clientAuth");
    const int port = test::free_port();
    redis_ = std::make_unique<test::ChildProcess>(
        std::vector<std::string>{"redis-server", "--bind", "127.0.0.1", "--port", std::to_string(port), "--save", "",
                                 "--appendonly", "no", "--dir", dir_.string()},
        (dir_ / "redis.log").string());
    redis_->wait_for_port(port, 20);
    redis_address_ = "127.0.0.1:" + std::to_string(port);
  }

  void TearDown() override {
    replicas_[0].reset();
    replicas_[1].reset();
    redis_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // Replica i (0 or 1), with mutual TLS on both ports, trusting `peer_ca` for
  // the others, serving certificate `cert` (default: its own).
  void start(int i, const std::string& peer_ca, std::string cert = "") {
    const std::string name = "replica-" + std::to_string(i + 1);
    if (cert.empty()) cert = name;
    replicas_[i] = std::make_unique<test::ServerProcess>(
        FILIGREE_SERVER_BINARY,
        std::vector<std::string>{"--redis", redis_address_, "--replica-id", name, "--data-dir", (dir_ / name).string(),
                                 "--tls-cert", (*pki_ / (cert + ".pem")).string(), "--tls-key", (*pki_ / (cert + ".key")).string(),
                                 "--tls-client-ca", (*pki_ / "ca.pem").string(), "--peer-ca", (*pki_ / peer_ca).string()},
        /*http=*/true);
  }

  // An engine's client of replica i, with its client certificate, expecting
  // the server's certificate to name `host` (default: the address).
  Client engine(int i, const std::string& host = "") const {
    grpc::SslCredentialsOptions options;
    options.pem_root_certs = read_file(*pki_ / "ca.pem");
    options.pem_private_key = read_file(*pki_ / "engine.key");
    options.pem_cert_chain = read_file(*pki_ / "engine.pem");
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(-1);
    if (!host.empty()) args.SetSslTargetNameOverride(host);
    return Client(grpc::CreateCustomChannel(replicas_[i]->address(), grpc::SslCredentials(options), args));
  }

  // A browser's gRPC-Web GetState over HTTPS to replica i (client
  // certificate: the engine's); the gRPC-Web frames it got back.
  test::Frames browser_get_state(int i, const SessionHandle& s) const {
    auto context = test::client_context(*pki_ / "ca.pem", *pki_ / "engine.pem", *pki_ / "engine.key");
    test::HttpsClient browser(replicas_[i]->http_address(), *context);
    v1::GetStateRequest request;
    request.set_session_id(s.session_id);
    auto http_request = test::grpc_web_request("GetState", request);
    http_request.set("x-session-id", s.session_id);
    http_request.set("x-filigree-token", s.viewer_token);
    const auto response = browser.exchange(http_request);
    EXPECT_EQ(response.result_int(), 200u);
    return test::parse_frames(response.body());
  }

  fs::path dir_;
  std::unique_ptr<test::Pki> pki_;
  std::unique_ptr<test::ChildProcess> redis_;
  std::string redis_address_;
  std::unique_ptr<test::ServerProcess> replicas_[2];
};

TEST_F(ClusterTls, ABrowserOnAnotherReplicaReachesTheSessionOverMutualTls) {
  start(0, "ca.pem");
  start(1, "ca.pem");
  Client owner = engine(0);
  const SessionHandle s = owner.create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", {}, "engine");
  ASSERT_EQ(owner.locate(s.session_id, s.viewer_token).replica_id(), "replica-1");
  // One pose, so that the state names a frame of its own.
  auto driver = owner.drive(s.session_id, s.editor_token, "engine");
  std::vector<float> pose = s.mesh.base_positions;
  for (std::size_t j = 0; j < pose.size(); j += 3) pose[j] += 0.01f;
  ASSERT_TRUE(driver->send(1, pose));
  std::optional<v1::Frame> frame;
  while ((frame = driver->read()) && frame->pose_id() < 1) {
  }
  ASSERT_TRUE(frame.has_value());
  driver->writes_done();
  ASSERT_TRUE(driver->finish().ok());
  const v1::SessionState direct = owner.state(s.session_id, s.viewer_token);
  ASSERT_GT(direct.version(), 0u);

  // Replica 2 does not serve the session: its bridge calls replica 1, over TLS.
  const test::Frames frames = browser_get_state(1, s);
  ASSERT_TRUE(frames.well_formed);
  EXPECT_NE(frames.trailer.find("grpc-status:0"), std::string::npos) << frames.trailer;
  ASSERT_EQ(frames.messages.size(), 1u);
  v1::SessionState state;
  ASSERT_TRUE(state.ParseFromString(frames.messages[0]));
  EXPECT_EQ(state.version(), direct.version());
  EXPECT_EQ(state.pose_size(), direct.pose_size());
  // Forwarded, not moved: replica 1 still serves it.
  EXPECT_EQ(owner.locate(s.session_id, s.viewer_token).replica_id(), "replica-1");
}

TEST_F(ClusterTls, AReplicaThatDoesNotTrustTheOtherFailsTheCallAndServesOn) {
  start(0, "ca.pem");
  start(1, "other-ca.pem");  // replica 1's certificate does not chain to it
  Client owner = engine(0);
  const SessionHandle s = owner.create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", {}, "engine");

  const test::Frames frames = browser_get_state(1, s);
  ASSERT_TRUE(frames.well_formed);
  EXPECT_TRUE(frames.messages.empty());
  EXPECT_NE(frames.trailer.find("grpc-status:14"), std::string::npos) << frames.trailer;  // UNAVAILABLE
  // Nothing else is harmed: both replicas answer, the session is where it was.
  EXPECT_NO_THROW(engine(1).list());
  EXPECT_NO_THROW(owner.state(s.session_id, s.viewer_token));
  EXPECT_EQ(owner.locate(s.session_id, s.viewer_token).replica_id(), "replica-1");
}

TEST_F(ClusterTls, AReplicaWhoseCertificateDoesNotNameItsAddressIsNotCalled) {
  start(0, "ca.pem", "misnamed");  // trusted CA, but not for 127.0.0.1
  start(1, "ca.pem");
  Client owner = engine(0, "elsewhere.test");
  const SessionHandle s = owner.create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", {}, "engine");
  ASSERT_EQ(owner.locate(s.session_id, s.viewer_token).replica_id(), "replica-1");
  const test::Frames frames = browser_get_state(1, s);
  ASSERT_TRUE(frames.well_formed);
  EXPECT_TRUE(frames.messages.empty());
  EXPECT_NE(frames.trailer.find("grpc-status:14"), std::string::npos) << frames.trailer;  // UNAVAILABLE
  EXPECT_NO_THROW(owner.state(s.session_id, s.viewer_token));
}

TEST_F(ClusterTls, PeerCaThatCannotServeIsRefusedAtStartSayingWhy) {
  const auto contains = [](const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; };
  // Without TLS there is nothing for it to verify.
  const test::ServerRun plaintext = test::run_server(FILIGREE_SERVER_BINARY, {"--peer-ca", (*pki_ / "ca.pem").string()});
  EXPECT_FALSE(plaintext.listened);
  EXPECT_NE(plaintext.status, 0);
  EXPECT_TRUE(contains(plaintext.output, "--peer-ca needs --tls-cert and --tls-key")) << plaintext.output;
  const std::vector<std::string> tls = {"--tls-cert", (*pki_ / "replica-1.pem").string(), "--tls-key",
                                        (*pki_ / "replica-1.key").string()};
  // Nothing forwards without replicas serving browsers: refused, not ignored.
  std::vector<std::string> alone = tls;
  alone.insert(alone.end(), {"--peer-ca", (*pki_ / "ca.pem").string()});
  const test::ServerRun unused = test::run_server(FILIGREE_SERVER_BINARY, alone);
  EXPECT_FALSE(unused.listened);
  EXPECT_NE(unused.status, 0);
  EXPECT_TRUE(contains(unused.output, "--peer-ca is for replicas")) << unused.output;
  // A file that is not there fails now, not on the first forwarded call.
  std::vector<std::string> replica = tls;
  replica.insert(replica.end(), {"--redis", redis_address_, "--http", "127.0.0.1:0", "--data-dir", (dir_ / "missing").string(),
                                 "--peer-ca", (dir_ / "nowhere.pem").string()});
  const test::ServerRun missing = test::run_server(FILIGREE_SERVER_BINARY, replica);
  EXPECT_FALSE(missing.listened);
  EXPECT_NE(missing.status, 0);
  EXPECT_TRUE(contains(missing.output, "--peer-ca " + (dir_ / "nowhere.pem").string() + " cannot be read")) << missing.output;
}

}  // namespace
}  // namespace filigree
