// Replicas behind a gRPC load balancer (DESIGN §4, issue 6), on loopback:
// Redis, three filigree-server replicas sharing it, and nginx routing by
// x-session-id with a consistent hash, all started and stopped here.

#include <algorithm>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include "filigree/client.h"
#include "server/state/redis_client.h"
#include "support/cluster.h"
#include "support/grpc_web_frames.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using test::ServerProcess;

constexpr int kReplicas = 3;
using test::Cluster;

// A unary call to one replica as a load balancer would make it (no
// x-filigree-route: the replica may take the session over).
grpc::Status get_state(const std::string& address, const SessionHandle& s, v1::SessionState* state) {
  auto stub = v1::Filigree::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  set_session_metadata(context, s.session_id, s.viewer_token);
  v1::GetStateRequest request;
  request.set_session_id(s.session_id);
  return stub->GetState(&context, request, state);
}

const std::string& bunny() {
  static const std::string bytes = test::file_bytes(test::shipped_path("bunny_small.obj"));
  return bytes;
}

// Pose i: every base vertex displaced along a smooth field that changes with i.
std::vector<float> pose(const SessionMesh& mesh, std::uint64_t i) {
  std::vector<float> p = mesh.base_positions;
  for (std::size_t v = 0; v < p.size() / 3; ++v) {
    const float y = mesh.base_positions[3 * v + 1];
    p[3 * v] += 0.01f * std::sin(0.15f * static_cast<float>(i) + 20.0f * y);
    p[3 * v + 2] += 0.005f * std::cos(0.1f * static_cast<float>(i));
  }
  return p;
}

// Sends pose `id` and reads frames until the one that acknowledges it;
// nullopt if the stream ended first.
std::optional<v1::Frame> send_and_wait(Driver& driver, const SessionMesh& mesh, std::uint64_t id) {
  if (!driver.send(id, pose(mesh, id))) return std::nullopt;
  std::optional<v1::Frame> f;
  while ((f = driver.read()) && f->pose_id() < id) {
  }
  return f;
}

double max_difference(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0.0;
  for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i) d = std::max(d, std::abs(double(a[i]) - double(b[i])));
  return d;
}

// A unary SubmitPose through `address`.
grpc::Status submit_pose(const std::string& address, const SessionHandle& s, std::uint64_t id) {
  auto stub = v1::Filigree::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  grpc::ClientContext context;
  set_session_metadata(context, s.session_id, s.editor_token);
  v1::DriveRequest request;
  request.set_session_id(s.session_id);
  request.set_pose_id(id);
  const std::vector<float> p = pose(s.mesh, id);
  request.mutable_positions()->Add(p.begin(), p.end());
  v1::SubmitPoseResponse response;
  return stub->SubmitPose(&context, request, &response);
}

// Waits (retrying with backoff) until `address` serves the session's state.
v1::SessionState state_when_served(const std::string& address, const SessionHandle& s) {
  v1::SessionState state;
  for (int attempt = 0; attempt < 100; ++attempt) {
    const grpc::Status status = get_state(address, s, &state);
    if (status.ok()) return state;
    EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE) << status.error_message();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // retry backoff
  }
  ADD_FAILURE() << "the session was never served at " << address;
  return state;
}

TEST(Cluster, SessionsSpreadOverReplicasAndEachSessionsCallsReachItsReplica) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  constexpr int kSessions = 30;
  std::vector<SessionHandle> sessions;
  int built = 0;
  for (int i = 0; i < kSessions; ++i) {
    sessions.push_back(lb.create_session(bunny(), "obj", {}, "spread"));
    built += sessions.back().cached ? 0 : 1;
  }
  // One replica preprocessed the mesh; the others loaded its hierarchy from Redis.
  EXPECT_EQ(built, 1);

  std::map<std::string, std::set<std::string>> by_replica;
  for (const auto& s : sessions) {
    const v1::SessionLocation first = lb.locate(s.session_id, s.viewer_token);
    // Through nginx, a session's calls reach the replica that serves it.
    EXPECT_TRUE(first.here()) << s.session_id << " is served by " << first.replica_id();
    for (int k = 0; k < 4; ++k) {
      lb.state(s.session_id, s.viewer_token);
      const v1::SessionLocation again = lb.locate(s.session_id, s.viewer_token);
      EXPECT_EQ(again.replica_id(), first.replica_id());
      EXPECT_TRUE(again.here());
    }
    by_replica[first.replica_id()].insert(s.session_id);
  }
  // 30 random ids over 3 replicas: each gets some (all on two: p ≈ 2e-5).
  EXPECT_EQ(by_replica.size(), std::size_t(kReplicas));
  // Each replica computes exactly the sessions routed to it.
  for (const auto& [replica, ids] : by_replica) {
    const int i = cluster.index_of(replica);
    ASSERT_GE(i, 0) << replica;
    Client direct(cluster.address(i));
    std::set<std::string> listed;
    for (const auto& e : direct.list()) listed.insert(e.session_id());
    EXPECT_EQ(listed, ids) << replica;
    const auto one = std::find_if(sessions.begin(), sessions.end(), [&](const auto& s) { return s.session_id == *ids.begin(); });
    ASSERT_NE(one, sessions.end());
    EXPECT_EQ(direct.locate(one->session_id, one->viewer_token).address(), cluster.address(i));
  }
}

TEST(Cluster, HierarchyBuiltByOneReplicaIsLoadedByAnother) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client first(cluster.address(0)), second(cluster.address(1));
  const SessionHandle a = first.create_session(bunny(), "obj", {}, "builder");
  EXPECT_FALSE(a.cached);
  const SessionHandle b = second.create_session(bunny(), "obj", {}, "loader");
  EXPECT_TRUE(b.cached) << "replica 2 preprocessed the mesh again";
  EXPECT_EQ(a.mesh.mesh_hash, b.mesh.mesh_hash);
  EXPECT_EQ(a.mesh.base_positions, b.mesh.base_positions);
  // Replica 2 keeps the fetched file in its own data directory.
  std::size_t files = 0;
  for (const auto& e : fs::directory_iterator(cluster.data_dir(1) / "hierarchies")) files += e.path().extension() == ".fgh";
  EXPECT_EQ(files, 1u);
}

TEST(Cluster, TwoReplicasGivenTheSameNewMeshAtOnceBuildItOnce) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  // The Armadillo (26k vertices) takes about a second to preprocess; the second
  // upload starts during the first build and must wait for it, not repeat it.
  const std::string armadillo = test::file_bytes(std::string(FILIGREE_REPO_DATA_DIR) + "/armadillo.off");
  SessionHandle a, b;
  std::thread first([&] { a = Client(cluster.address(0)).create_session(armadillo, "off", {}, "first"); });
  // The second upload starts while the first build runs: once its claim is in Redis.
  server::RedisClient redis(cluster.redis_address(), std::chrono::milliseconds(2000));
  bool claimed = false;
  for (int i = 0; i < 400 && !claimed; ++i) {
    claimed = !redis.command({"KEYS", "filigree:building:*"}).elements.empty();
    if (!claimed) std::this_thread::sleep_for(std::chrono::milliseconds(5));  // polls the condition, bounded
  }
  EXPECT_TRUE(claimed) << "the first replica never claimed the build";
  std::thread second([&] { b = Client(cluster.address(1)).create_session(armadillo, "off", {}, "second"); });
  first.join();
  second.join();
  EXPECT_NE(a.cached, b.cached) << "both replicas built the hierarchy, or neither did";
  EXPECT_EQ(a.mesh.base_positions, b.mesh.base_positions);
}

TEST(Cluster, DirectRoutingNamesTheOwnerInsteadOfTakingTheSessionOver) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "direct");
  const v1::SessionLocation where = lb.locate(s.session_id, s.viewer_token);
  const int owner = cluster.index_of(where.replica_id());
  ASSERT_GE(owner, 0);
  EXPECT_EQ(where.address(), cluster.address(owner));
  const int other = (owner + 1) % kReplicas;
  // A direct call to a replica that does not serve the session: UNAVAILABLE naming the owner.
  auto channel = grpc::CreateChannel(cluster.address(other), grpc::InsecureChannelCredentials());
  auto stub = v1::Filigree::NewStub(channel);
  grpc::ClientContext context;
  context.AddMetadata("x-filigree-token", s.viewer_token);
  context.AddMetadata("x-session-id", s.session_id);
  context.AddMetadata("x-filigree-route", "direct");
  v1::GetStateRequest request;
  request.set_session_id(s.session_id);
  v1::SessionState state;
  const grpc::Status status = stub->GetState(&context, request, &state);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(status.error_message().find(where.address()), std::string::npos) << status.error_message();
  const auto& trailers = context.GetServerTrailingMetadata();
  const auto it = trailers.find("x-filigree-owner");
  ASSERT_NE(it, trailers.end());
  EXPECT_EQ(std::string(it->second.data(), it->second.size()), cluster.address(owner));
  // The owner still serves it.
  EXPECT_EQ(lb.locate(s.session_id, s.viewer_token).replica_id(), where.replica_id());

  // An engine routing itself with the client library: locate, then call the owner directly.
  Client engine(where.address());
  engine.set_routing(Routing::kDirect);
  auto driver = engine.drive(s.session_id, s.editor_token, "engine");
  std::optional<v1::Frame> f = send_and_wait(*driver, s.mesh, 1);
  EXPECT_TRUE(f.has_value());
  driver->writes_done();
  EXPECT_TRUE(driver->finish().ok());
  Client wrong(cluster.address(other));
  wrong.set_routing(Routing::kDirect);
  try {
    wrong.state(s.session_id, s.viewer_token);
    ADD_FAILURE() << "a replica that does not serve the session answered";
  } catch (const ClientError& e) {
    EXPECT_EQ(e.code(), grpc::StatusCode::UNAVAILABLE);
  }
  EXPECT_EQ(lb.locate(s.session_id, s.viewer_token).replica_id(), where.replica_id());
}

TEST(Cluster, ASessionMovesToTheReplicaItsCallsReach) {
  // What happens when a load balancer's routing changes (a replica came back):
  // the replica that now gets the calls asks for the session, the owner hands
  // it over, and its streams end telling clients to reconnect.
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "moving");
  // No reconnection: this test looks at how the old owner's streams end.
  Reconnect no_reconnect;
  no_reconnect.enabled = false;
  auto driver = lb.drive(s.session_id, s.editor_token, "moving", no_reconnect);
  std::optional<v1::Frame> f = send_and_wait(*driver, s.mesh, 1);
  ASSERT_TRUE(f.has_value());
  const std::uint64_t version = f->version();
  const int owner = cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id());
  const int other = (owner + 1) % kReplicas;
  auto watcher = lb.watch(s.session_id, s.viewer_token, version, no_reconnect);

  v1::SessionState state;
  const grpc::Status first = get_state(cluster.address(other), s, &state);
  EXPECT_EQ(first.error_code(), grpc::StatusCode::UNAVAILABLE) << "the other replica served the session without a hand-over";
  state = state_when_served(cluster.address(other), s);
  EXPECT_EQ(state.version(), version);
  EXPECT_EQ(std::vector<float>(state.pose().begin(), state.pose().end()), pose(s.mesh, 1));
  EXPECT_EQ(Client(cluster.address(other)).locate(s.session_id, s.viewer_token).replica_id(), "replica-" + std::to_string(other + 1));
  // The old owner's streams end with UNAVAILABLE, saying the session moved.
  while (watcher->read()) {
  }
  const grpc::Status watch_status = watcher->finish();
  EXPECT_EQ(watch_status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(watch_status.error_message().find("moved"), std::string::npos) << watch_status.error_message();
  while (driver->read()) {
  }
  EXPECT_EQ(driver->finish().error_code(), grpc::StatusCode::UNAVAILABLE);
}

TEST(Cluster, BadSharedStateIsAClearErrorAndHarmsNoOtherSession) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client first(cluster.address(0));
  const SessionHandle good = first.create_session(bunny(), "obj", {}, "good");
  server::RedisClient redis(cluster.redis_address(), std::chrono::milliseconds(2000));

  // A record that is not a record, under a well-formed id.
  const std::string bad_id = "0123456789abcdef0123";
  redis.command({"SET", "filigree:session:" + bad_id, "not a protobuf \xff\xff"});
  v1::SessionState state;
  SessionHandle fake = good;
  fake.session_id = bad_id;
  grpc::Status status = get_state(cluster.address(1), fake, &state);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DATA_LOSS) << status.error_message();
  EXPECT_NE(status.error_message().find("record"), std::string::npos) << status.error_message();

  // A corrupt hierarchy blob: a replica that must load it refuses with the reason.
  const auto keys = redis.command({"KEYS", "filigree:hierarchy:*"});
  ASSERT_EQ(keys.elements.size(), 1u);
  redis.command({"SETRANGE", keys.elements[0].str, "100", "garbage garbage garbage"});
  cluster.kill(0);
  int attempts = 0;
  while ((status = get_state(cluster.address(1), good, &state)).error_code() == grpc::StatusCode::UNAVAILABLE) {
    ASSERT_LT(++attempts, 100) << status.error_message();
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // until the dead replica's lease expires
  }
  EXPECT_EQ(status.error_code(), grpc::StatusCode::DATA_LOSS) << status.error_message();
  EXPECT_NE(status.error_message().find("checksum"), std::string::npos) << status.error_message();

  // The replica still serves; an upload of the same mesh rebuilds the corrupt shared hierarchy.
  Client second(cluster.address(1));
  EXPECT_NO_THROW(second.list());
  const SessionHandle rebuilt = second.create_session(bunny(), "obj", {}, "rebuild");
  EXPECT_FALSE(rebuilt.cached);
  EXPECT_EQ(second.state(rebuilt.session_id, rebuilt.viewer_token).version(), 0u);
  // Proposed ids: malformed, or taken.
  v1::CreateSessionRequest begin;
  for (const std::string& id : {std::string("NOT-HEX"), good.session_id}) {
    auto stub = v1::Filigree::NewStub(grpc::CreateChannel(cluster.address(1), grpc::InsecureChannelCredentials()));
    grpc::ClientContext context;
    auto stream = stub->CreateSession(&context);
    v1::CreateSessionRequest r;
    r.mutable_begin()->set_format("obj");
    r.mutable_begin()->set_total_bytes(bunny().size());
    r.mutable_begin()->set_session_id(id);
    ASSERT_TRUE(stream->Write(r));
    r.Clear();
    r.set_chunk(bunny());
    stream->Write(r);
    stream->WritesDone();
    for (v1::CreateSessionResponse response; stream->Read(&response);) {
    }
    const grpc::Status created = stream->Finish();
    EXPECT_EQ(created.error_code(),
              id == good.session_id ? grpc::StatusCode::ALREADY_EXISTS : grpc::StatusCode::INVALID_ARGUMENT)
        << created.error_message();
  }
}

TEST(Cluster, WithoutRedisChangesAreRefusedNotLostAndTheServerLives) {
  // A replica that cannot reach Redis at start says so and exits.
  const int closed_port = test::free_port();
  EXPECT_THROW(ServerProcess(FILIGREE_SERVER_BINARY, {"--redis", "127.0.0.1:" + std::to_string(closed_port)}),
               std::runtime_error);

  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "store-down");
  v1::DriveRequest request;
  request.set_session_id(s.session_id);
  request.set_pose_id(1);
  const std::vector<float> p = pose(s.mesh, 1);
  request.mutable_positions()->Add(p.begin(), p.end());
  auto stub = v1::Filigree::NewStub(grpc::CreateChannel(cluster.lb(), grpc::InsecureChannelCredentials()));
  {
    grpc::ClientContext context;
    set_session_metadata(context, s.session_id, s.editor_token);
    v1::SubmitPoseResponse response;
    ASSERT_TRUE(stub->SubmitPose(&context, request, &response).ok());
  }
  cluster.stop_redis();
  grpc::ClientContext context;
  set_session_metadata(context, s.session_id, s.editor_token);
  v1::SubmitPoseResponse response;
  request.set_pose_id(2);
  const grpc::Status status = stub->SubmitPose(&context, request, &response);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::UNAVAILABLE);
  EXPECT_NE(status.error_message().find("Redis"), std::string::npos) << status.error_message();
  // Every replica still answers.
  for (int i = 0; i < kReplicas; ++i) EXPECT_NO_THROW(Client(cluster.address(i)).list()) << i;
}

// A browser's gRPC-Web unary call (HTTP/1.1, Connection: close) to
// `address`; returns the response body (gRPC-Web frames).
std::string grpc_web_call(const std::string& address, const std::string& method, const std::string& session,
                          const std::string& token, const std::string& message) {
  const auto colon = address.rfind(':');
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(std::stoi(address.substr(colon + 1))));
  inet_pton(AF_INET, address.substr(0, colon).c_str(), &a.sin_addr);
  EXPECT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a), 0);
  const std::string body = test::frame_bytes(0, message);
  const std::string request = "POST /filigree.v1.Filigree/" + method + " HTTP/1.1\r\nHost: " + address +
                              "\r\nContent-Type: application/grpc-web+proto\r\nx-session-id: " + session +
                              "\r\nx-filigree-token: " + token + "\r\nContent-Length: " + std::to_string(body.size()) +
                              "\r\nConnection: close\r\n\r\n" + body;
  EXPECT_EQ(write(fd, request.data(), request.size()), static_cast<ssize_t>(request.size()));
  std::string response;
  char buffer[65536];
  for (ssize_t n; (n = read(fd, buffer, sizeof buffer)) > 0;) response.append(buffer, static_cast<std::size_t>(n));
  close(fd);
  const auto end_of_headers = response.find("\r\n\r\n");
  if (end_of_headers == std::string::npos) return {};
  const std::string headers = response.substr(0, end_of_headers);
  std::string rest = response.substr(end_of_headers + 4), out;
  if (headers.find("chunked") == std::string::npos) return rest;
  // Chunked transfer coding: size line, data, CRLF; a zero size ends it.
  for (std::size_t at = 0;;) {
    const auto line_end = rest.find("\r\n", at);
    if (line_end == std::string::npos) break;
    const std::size_t size = std::stoul(rest.substr(at, line_end - at), nullptr, 16);
    if (size == 0) break;
    out += rest.substr(line_end + 2, size);
    at = line_end + 2 + size + 2;
  }
  return out;
}

TEST(Cluster, ABrowserOnAnotherReplicaReachesTheSessionWithoutMovingIt) {
  // nginx hashes gRPC and HTTP calls on two rings (the replicas' ports
  // differ), so a browser may reach another replica than the engines: that
  // replica's gRPC-Web bridge calls the replica that serves the session.
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas, 1500, /*http=*/true);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "engine");
  auto driver = lb.drive(s.session_id, s.editor_token, "engine");
  std::optional<v1::Frame> f = send_and_wait(*driver, s.mesh, 1);
  ASSERT_TRUE(f.has_value());
  const std::string owner = lb.locate(s.session_id, s.viewer_token).replica_id();
  const int other = (cluster.index_of(owner) + 1) % kReplicas;

  v1::GetStateRequest request;
  request.set_session_id(s.session_id);
  const std::string body =
      grpc_web_call(cluster.http_address(other), "GetState", s.session_id, s.viewer_token, request.SerializeAsString());
  const test::Frames frames = test::parse_frames(body);
  ASSERT_TRUE(frames.well_formed) << body;
  ASSERT_EQ(frames.messages.size(), 1u) << "no data frame: " << body;
  v1::SessionState state;
  ASSERT_TRUE(state.ParseFromString(frames.messages[0]));
  EXPECT_EQ(state.version(), f->version());
  EXPECT_NE(frames.trailer.find("grpc-status:0"), std::string::npos) << frames.trailer;
  // Through nginx's HTTP port (the shipped configuration's second server block) too.
  const std::string via_lb =
      grpc_web_call(cluster.lb_http(), "GetState", s.session_id, s.viewer_token, request.SerializeAsString());
  EXPECT_NE(via_lb.find("grpc-status:0"), std::string::npos) << via_lb;
  // The session stayed where the engines' calls go; the engine's stream lives on.
  EXPECT_EQ(lb.locate(s.session_id, s.viewer_token).replica_id(), owner);
  EXPECT_TRUE(send_and_wait(*driver, s.mesh, 2).has_value());
  driver->writes_done();
  EXPECT_TRUE(driver->finish().ok());
}

TEST(Cluster, AReplicaThatWasFrozenPastItsLeaseCannotOverwriteTheNewOwner) {
  // Split brain: the owner freezes (SIGSTOP) while a client still streams to
  // it directly; another replica takes the session over and accepts a pose;
  // the old owner wakes up with a pose in its socket. Its writes are fenced
  // by the lease: that pose is never acknowledged and the new owner's stands.
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "frozen");
  const int owner = cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id());
  Client direct(cluster.address(owner));
  direct.set_routing(Routing::kDirect);
  Reconnect no_reconnect;  // this test looks at how the frozen replica's stream ends
  no_reconnect.enabled = false;
  auto driver = direct.drive(s.session_id, s.editor_token, "old-route", no_reconnect);
  ASSERT_TRUE(send_and_wait(*driver, s.mesh, 1).has_value());

  cluster.pause(owner);
  const int other = (owner + 1) % kReplicas;
  state_when_served(cluster.address(other), s);  // takes the session over once the lease expires
  ASSERT_TRUE(submit_pose(cluster.address(other), s, 5).ok());
  ASSERT_TRUE(driver->send(2, pose(s.mesh, 2)));  // waits in the frozen replica's socket
  cluster.resume(owner);

  while (auto f = driver->read()) EXPECT_NE(f->pose_id(), 2u) << "the frozen replica acknowledged a pose";
  EXPECT_EQ(driver->finish().error_code(), grpc::StatusCode::UNAVAILABLE);
  const v1::SessionState state = state_when_served(cluster.address(other), s);
  EXPECT_EQ(std::vector<float>(state.pose().begin(), state.pose().end()), pose(s.mesh, 5));
  EXPECT_EQ(Client(cluster.address(other)).locate(s.session_id, s.viewer_token).replica_id(), "replica-" + std::to_string(other + 1));
}

TEST(Cluster, AStoppedReplicaHandsItsSessionsOverAtOnce) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "stopping");
  ASSERT_TRUE(submit_pose(cluster.lb(), s, 3).ok());
  const int owner = cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id());
  EXPECT_EQ(cluster.terminate(owner), 0);
  // SIGTERM released the lease: no replica holds it until the next call.
  server::RedisClient redis(cluster.redis_address(), std::chrono::milliseconds(2000));
  EXPECT_TRUE(redis.command({"GET", "filigree:lease:" + s.session_id}).nil());
  const v1::SessionState state = lb.state(s.session_id, s.viewer_token);  // no UNAVAILABLE to wait out
  EXPECT_EQ(std::vector<float>(state.pose().begin(), state.pose().end()), pose(s.mesh, 3));
  EXPECT_NE(cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id()), owner);
}

TEST(Cluster, SessionSurvivesItsReplicaBeingKilledUnderLoad) {
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "failover");
  const int owner = cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id());
  ASSERT_GE(owner, 0);
  // Positions of a chunked frame, decoded after the keyframe it needs.
  const auto positions_of = [&](const v1::Frame& frame, const v1::Frame* keyframe) {
    FrameDecoder decoder(s.mesh.rest_positions);
    if (keyframe != nullptr && frame.keyframe_version() != frame.version()) decoder.decode(*keyframe);
    return decoder.decode(frame);
  };
  constexpr std::uint64_t kPoses = 80, kKillAfter = 25;

  // Watchers: they reconnect by themselves (Reconnect) from the last version
  // they delivered; versions only grow.
  struct WatchLog {
    std::mutex mutex;
    std::condition_variable changed;
    std::uint64_t last_version = 0;
    bool seen_any = false;
    v1::Frame last, keyframe;
    std::atomic<int> reconnects{0};
    std::unique_ptr<Watcher> stream;
  };
  std::vector<std::unique_ptr<WatchLog>> logs;
  std::vector<std::thread> watchers;
  Client watching(cluster.lb());
  for (int w = 0; w < 2; ++w) {
    logs.push_back(std::make_unique<WatchLog>());
    WatchLog* log = logs.back().get();
    Reconnect again;
    again.on_reconnect = [log](const grpc::Status&, int) { ++log->reconnects; };
    log->stream = watching.watch(s.session_id, s.viewer_token, 0, again);
    watchers.emplace_back([log] {
      while (auto f = log->stream->read()) {
        std::lock_guard lock(log->mutex);
        const bool keyframe = f->keyframe_version() == f->version();
        if (keyframe) log->keyframe = *f;
        // After a reconnect, the keyframe the next frame needs comes first,
        // whatever its version (WatchRequest.after_version).
        if (keyframe && log->seen_any && f->version() <= log->last_version) continue;
        if (log->seen_any) {
          EXPECT_GT(f->version(), log->last_version);
        }
        log->seen_any = true;
        log->last_version = f->version();
        log->last = *f;
        log->changed.notify_all();
      }
      EXPECT_EQ(log->stream->finish().error_code(), grpc::StatusCode::CANCELLED) << "a watcher gave up";
    });
  }

  // The driver, lock-step: pose i, then wait for the frame that acknowledges
  // it. It reconnects by itself (Reconnect), re-sending the pose in flight.
  std::atomic<std::uint64_t> acked{0};
  std::atomic<bool> killed{false};
  std::thread killer([&] {
    // Kill the owner while poses stream (the driver does not pause for it).
    while (acked < kKillAfter) std::this_thread::yield();
    cluster.kill(owner);
    killed = true;
  });
  std::atomic<int> reconnects{0};
  Reconnect reconnect;
  reconnect.on_reconnect = [&](const grpc::Status& why, int) {
    EXPECT_NE(why.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << why.error_message();
    ++reconnects;
  };
  auto driver = lb.drive(s.session_id, s.editor_token, "failover", reconnect);
  std::uint64_t acked_version = 0;
  bool checked_restore = false;
  for (std::uint64_t next = 1; next <= kPoses; ++next) {
    for (int attempt = 0; killed && !checked_restore; ++attempt) {
      // Nothing acknowledged is lost: the new replica has the acknowledged pose.
      try {
        const v1::SessionState state = lb.state(s.session_id, s.viewer_token);
        EXPECT_GE(state.version(), acked_version);
        EXPECT_EQ(std::vector<float>(state.pose().begin(), state.pose().end()), pose(s.mesh, next - 1));
        checked_restore = true;
      } catch (const ClientError& e) {
        ASSERT_LT(attempt, 100) << "the session did not come back: " << e.what();
        std::this_thread::sleep_for(std::chrono::milliseconds(100));  // backoff, as a client would
      }
    }
    const std::optional<v1::Frame> f = send_and_wait(*driver, s.mesh, next);
    ASSERT_TRUE(f.has_value()) << "the driver gave up at pose " << next << ": " << driver->finish().error_message();
    EXPECT_EQ(f->pose_id(), next);
    EXPECT_GT(f->version(), acked_version) << "versions go on from the last acknowledged one";
    acked_version = f->version();
    acked = next;
  }
  EXPECT_EQ(driver->unacknowledged(), 0u);
  driver->writes_done();
  EXPECT_TRUE(driver->finish().ok());
  killer.join();
  EXPECT_TRUE(checked_restore);
  EXPECT_GE(reconnects, 1);

  const v1::SessionLocation now = lb.locate(s.session_id, s.viewer_token);
  EXPECT_NE(cluster.index_of(now.replica_id()), owner) << "the dead replica still owns the session";
  const v1::SessionState final_state = lb.state(s.session_id, s.viewer_token);
  EXPECT_EQ(final_state.version(), acked_version);
  EXPECT_EQ(std::vector<float>(final_state.pose().begin(), final_state.pose().end()), pose(s.mesh, kPoses));

  // Watchers catch up with the last frame after reconnecting.
  for (auto& log : logs) {
    std::unique_lock lock(log->mutex);
    EXPECT_TRUE(log->changed.wait_for(lock, std::chrono::seconds(30), [&] { return log->last_version >= acked_version; }))
        << "a watcher stopped at version " << log->last_version << " of " << acked_version;
    EXPECT_GE(log->reconnects, 1);
    log->stream->cancel();
  }
  for (auto& t : watchers) t.join();

  // The same poses without a failure, on a fresh session, give the same result.
  const SessionHandle reference = lb.create_session(bunny(), "obj", {}, "reference");
  {
    auto driver = lb.drive(reference.session_id, reference.editor_token, "reference");
    for (std::uint64_t i = 1; i <= kPoses; ++i) ASSERT_TRUE(driver->send(i, pose(reference.mesh, i)));
    std::optional<v1::Frame> f;
    while ((f = driver->read()) && f->pose_id() < kPoses) {
    }
    ASSERT_TRUE(f.has_value());
    driver->writes_done();
    driver->finish();
  }
  const v1::SessionState expected = lb.state(reference.session_id, reference.viewer_token);
  // Equal within what each frame states: a sparse frame's vertices may come
  // from a keyframe within the error target, and histories differ.
  const DecodedFrame got = positions_of(final_state.frame(), &final_state.keyframe());
  const DecodedFrame want = positions_of(expected.frame(), &expected.keyframe());
  EXPECT_LE(max_difference(got.positions, want.positions), got.max_error + want.max_error + 1e-6);
  for (auto& log : logs) {
    const DecodedFrame last = positions_of(log->last, &log->keyframe);
    EXPECT_LE(max_difference(last.positions, want.positions), last.max_error + want.max_error + 1e-6);
  }
}

// The edit history's calls on one replica (a direct call may take the session
// over, as a load balancer's would).
class HistoryAt {
 public:
  HistoryAt(const std::string& address, const SessionHandle& s)
      : stub_(v1::Filigree::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()))), s_(s) {}

  // `author` moves base vertices `vertices` up by `dy` from the base pose, in gesture `gesture`.
  void move(const std::string& author, const std::vector<std::uint32_t>& vertices, float dy, std::uint64_t gesture) {
    grpc::ClientContext context;
    set_session_metadata(context, s_.session_id, s_.editor_token);
    v1::DriveRequest r;
    r.set_session_id(s_.session_id);
    r.set_client_name(author);
    r.set_gesture_id(gesture);
    for (const std::uint32_t v : vertices) {
      r.add_indices(v);
      r.add_positions(s_.mesh.base_positions[3 * v]);
      r.add_positions(s_.mesh.base_positions[3 * v + 1] + dy);
      r.add_positions(s_.mesh.base_positions[3 * v + 2]);
    }
    v1::SubmitPoseResponse answer;
    const grpc::Status status = stub_->SubmitPose(&context, r, &answer);
    ASSERT_TRUE(status.ok()) << status.error_message();
  }
  v1::UndoResponse undo(const std::string& author, bool redo = false) {
    grpc::ClientContext context;
    set_session_metadata(context, s_.session_id, s_.editor_token);
    v1::UndoRequest r;
    r.set_session_id(s_.session_id);
    r.set_client_name(author);
    v1::UndoResponse answer;
    const grpc::Status status = redo ? stub_->Redo(&context, r, &answer) : stub_->Undo(&context, r, &answer);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return answer;
  }
  v1::Checkpoint checkpoint(const std::string& author, const std::string& name) {
    grpc::ClientContext context;
    set_session_metadata(context, s_.session_id, s_.editor_token);
    v1::CreateCheckpointRequest r;
    r.set_session_id(s_.session_id);
    r.set_client_name(author);
    r.set_name(name);
    v1::Checkpoint made;
    const grpc::Status status = stub_->CreateCheckpoint(&context, r, &made);
    EXPECT_TRUE(status.ok()) << status.error_message();
    return made;
  }
  grpc::Status history(v1::History* out) {
    grpc::ClientContext context;
    set_session_metadata(context, s_.session_id, s_.viewer_token);
    v1::GetHistoryRequest r;
    r.set_session_id(s_.session_id);
    return stub_->GetHistory(&context, r, out);
  }
  // Each base vertex's height above the base pose in the merged pose.
  std::vector<float> heights() {
    grpc::ClientContext context;
    set_session_metadata(context, s_.session_id, s_.viewer_token);
    v1::GetStateRequest r;
    r.set_session_id(s_.session_id);
    v1::SessionState state;
    const grpc::Status status = stub_->GetState(&context, r, &state);
    EXPECT_TRUE(status.ok()) << status.error_message();
    std::vector<float> out(s_.mesh.base_positions.size() / 3, 0.0f);
    for (std::size_t v = 0; v < out.size() && 3 * v + 1 < static_cast<std::size_t>(state.pose_size()); ++v)
      out[v] = state.pose(static_cast<int>(3 * v + 1)) - s_.mesh.base_positions[3 * v + 1];
    return out;
  }

 private:
  std::unique_ptr<v1::Filigree::Stub> stub_;
  SessionHandle s_;
};

// Heights of zero but for `set`, against `got`.
void expect_heights(const std::vector<float>& got, std::initializer_list<std::pair<std::uint32_t, float>> set) {
  std::vector<float> want(got.size(), 0.0f);
  for (const auto& [v, h] : set) want.at(v) = h;
  for (std::size_t v = 0; v < got.size(); ++v) EXPECT_NEAR(got[v], want[v], 1e-6) << "base vertex " << v;
}

TEST(Cluster, TheEditHistoryFailsOverWithTheSession) {
  // Editors change a session on replica A and one undoes; A is killed
  // (SIGKILL: nothing saved on the way out). Replica B takes the session over
  // from Redis with its history: the same entries, and undo and redo go on.
  Cluster cluster(FILIGREE_SERVER_BINARY, kReplicas);
  Client lb(cluster.lb());
  const SessionHandle s = lb.create_session(bunny(), "obj", {}, "history");
  const int a = cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id());
  ASSERT_GE(a, 0);
  HistoryAt on_a(cluster.address(a), s);
  on_a.move("ana", {1, 2}, 0.01f, 11);
  on_a.move("ben", {3}, 0.02f, 21);
  on_a.move("ana", {1, 2}, 0.03f, 11);  // the same gesture: one entry
  on_a.move("cleo", {4}, 0.04f, 31);
  const v1::Checkpoint made = on_a.checkpoint("cleo", "before ben's second");
  on_a.move("ben", {2}, 0.05f, 22);  // over Ana's vertex 2
  // Ben's undo gives vertex 2 back to Ana. Once it is answered, the history
  // is in Redis (undo, redo and checkpoints save it before answering).
  ASSERT_EQ(on_a.undo("ben").outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(on_a.heights(), {{1, 0.03f}, {2, 0.03f}, {3, 0.02f}, {4, 0.04f}});
  v1::History before;
  ASSERT_TRUE(on_a.history(&before).ok());
  ASSERT_EQ(before.entries_size(), 5) << before.DebugString();
  ASSERT_EQ(before.checkpoints_size(), 1);
  EXPECT_TRUE(before.entries(3).undone());

  cluster.kill(a);
  const int b = (a + 1) % kReplicas;
  state_when_served(cluster.address(b), s);  // B takes the session over once A's lease expires
  EXPECT_EQ(Client(cluster.address(b)).locate(s.session_id, s.viewer_token).replica_id(), "replica-" + std::to_string(b + 1));
  HistoryAt on_b(cluster.address(b), s);
  v1::History after;
  ASSERT_TRUE(on_b.history(&after).ok());
  ASSERT_EQ(after.entries_size(), before.entries_size()) << "the history was not saved to Redis:\n" << after.DebugString();
  for (int i = 0; i < after.entries_size(); ++i)
    EXPECT_EQ(after.entries(i).SerializeAsString(), before.entries(i).SerializeAsString())
        << "entry " << i << ": " << after.entries(i).DebugString() << " was " << before.entries(i).DebugString();
  ASSERT_EQ(after.checkpoints_size(), 1);
  EXPECT_EQ(after.checkpoints(0).SerializeAsString(), made.SerializeAsString());
  EXPECT_EQ(after.first_seq(), before.first_seq());
  expect_heights(on_b.heights(), {{1, 0.03f}, {2, 0.03f}, {3, 0.02f}, {4, 0.04f}});

  // Undo and redo go on on B: Ben's redo takes vertex 2 back, Ana's undo
  // restores her vertex 1 (vertex 2 is Ben's again), Cleo's undo her 4.
  const v1::UndoResponse redone = on_b.undo("ben", /*redo=*/true);
  EXPECT_EQ(redone.outcome(), v1::UndoResponse::OUTCOME_DONE) << redone.message();
  EXPECT_EQ(redone.entry(), before.entries(3).seq());
  expect_heights(on_b.heights(), {{1, 0.03f}, {2, 0.05f}, {3, 0.02f}, {4, 0.04f}});
  const v1::UndoResponse undone = on_b.undo("ana");
  EXPECT_EQ(undone.outcome(), v1::UndoResponse::OUTCOME_PARTIAL) << undone.message();
  EXPECT_EQ(undone.entry(), before.entries(0).seq());
  expect_heights(on_b.heights(), {{2, 0.05f}, {3, 0.02f}, {4, 0.04f}});
  EXPECT_EQ(on_b.undo("cleo").outcome(), v1::UndoResponse::OUTCOME_DONE);
  expect_heights(on_b.heights(), {{2, 0.05f}, {3, 0.02f}});
  v1::History later;
  ASSERT_TRUE(on_b.history(&later).ok());
  ASSERT_EQ(later.entries_size(), before.entries_size() + 3);
  EXPECT_GT(later.entries(before.entries_size()).seq(), before.entries().rbegin()->seq()) << "entry numbers go on";
}

}  // namespace
}  // namespace filigree
