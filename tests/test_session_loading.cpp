// Loading a session that is not in memory (evicted, or written by another
// replica) reads its record and hierarchy and builds its model: seconds at a
// million vertices. It must not happen on gRPC's callback threads, which
// every call of the server shares (two on a 2-core machine): while loads are
// held up, calls on sessions in memory are still answered, and the loads
// finish once they can.
//
// In-process: the service over a session store whose loads wait at a gate
// the test opens. Nothing waits on time: the test waits for the loads to
// reach the gate, under a generous deadline that only bounds a failure.

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "filigree/v1/filigree.grpc.pb.h"
#include "preprocess/preprocess.h"
#include "server/filigree_service.h"
#include "server/hierarchy_cache.h"
#include "server/secret.h"
#include "server/session_registry.h"
#include "server/state/file_session_store.h"
#include "support/test_meshes.h"

namespace filigree::server {
namespace {

using namespace std::chrono_literals;
// How long the test waits for what must happen; a bound on a failure only.
constexpr auto kPatience = 20s;

// A file store whose load() waits while the gate is closed.
class GatedStore final : public SessionStore {
 public:
  explicit GatedStore(SessionStore& inner) : inner_(inner) {}

  void close_gate() {
    std::lock_guard lock(mutex_);
    open_ = false;
  }
  void open_gate() {
    std::lock_guard lock(mutex_);
    open_ = true;
    changed_.notify_all();
  }
  // Whether `n` loads are waiting at the gate within kPatience.
  bool wait_for_waiting(std::size_t n) {
    std::unique_lock lock(mutex_);
    return changed_.wait_for(lock, kPatience, [&] { return waiting_ >= n; });
  }
  std::size_t waiting() {
    std::lock_guard lock(mutex_);
    return waiting_;
  }

  std::optional<SessionRecord> load(const std::string& id) override {
    {
      std::unique_lock lock(mutex_);
      ++waiting_;
      changed_.notify_all();
      changed_.wait(lock, [&] { return open_; });
      --waiting_;
    }
    return inner_.load(id);
  }
  bool shared() const override { return inner_.shared(); }
  bool create(const SessionRecord& r) override { return inner_.create(r); }
  bool save(const SessionRecord& r) override { return inner_.save(r); }
  bool save_progress(const std::string& id, const SessionProgress& p) override { return inner_.save_progress(id, p); }
  bool exists(const std::string& id) override { return inner_.exists(id); }
  void remove(const std::string& id) override { inner_.remove(id); }
  std::vector<std::string> list() override { return inner_.list(); }
  Claim claim(const std::string& id, bool take_over) override { return inner_.claim(id, take_over); }
  Renewal renew(const std::string& id, bool may_hand_off) override { return inner_.renew(id, may_hand_off); }
  void release(const std::string& id) override { inner_.release(id); }

 private:
  SessionStore& inner_;
  std::mutex mutex_;
  std::condition_variable changed_;
  bool open_ = true;
  std::size_t waiting_ = 0;
};

// One JoinSession in flight (the client's callback API).
struct PendingJoin {
  grpc::ClientContext context;
  v1::JoinSessionRequest request;
  v1::SessionInfo response;
  grpc::Status status;
  bool done = false;
};

class SessionLoading : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("filigree_loading_" + random_token());
    std::filesystem::create_directories(dir_);
    files_ = std::make_unique<FileSessionStore>(dir_ / "sessions");
    gated_ = std::make_unique<GatedStore>(*files_);
    cache_ = std::make_unique<HierarchyCache>(dir_ / "hierarchies");
    registry_ = std::make_unique<SessionRegistry>(*cache_, *gated_, RegistryLimits{});
    ServiceLimits limits;
    limits.session_loads = session_loads();
    service_ = std::make_unique<FiligreeService>(*registry_, *cache_, limits);
    grpc::ServerBuilder builder;
    int port = 0;
    builder.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &port);
    builder.RegisterService(service_.get());
    server_ = builder.BuildAndStart();
    ASSERT_TRUE(server_);
    stub_ = v1::Filigree::NewStub(grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials()));
  }
  void TearDown() override {
    gated_->open_gate();  // a failed test must not leave a load waiting
    if (server_) server_->Shutdown();
    EXPECT_TRUE(wait_for_calls()) << "a call outlived the server";
    server_.reset();
    service_.reset();
    registry_.reset();
    std::filesystem::remove_all(dir_);
  }

  // A session of a small mesh; returns its id (tokens from its record).
  std::string create_session() {
    PreprocessOptions o;
    o.base_vertices = 60;
    std::string key;
    auto h = cache_->get_or_build(test::icosphere(3), o, &key, nullptr);
    return registry_->create(h, key, {}, {})->id();
  }
  // Loads at once: as many as the test holds up, unless a test is about the bound.
  virtual unsigned session_loads() const { return 64; }
  std::string editor_token(const std::string& id) { return files_->load(id)->editor_token; }

  // Starts a JoinSession of session `id`; the fixture keeps the call until
  // it is answered, even past a failed test's end.
  void start_join(const std::string& id) {
    calls_.push_back(std::make_unique<PendingJoin>());
    PendingJoin& call = *calls_.back();
    call.request.set_session_id(id);
    call.context.AddMetadata("x-filigree-token", editor_token(id));
    stub_->async()->JoinSession(&call.context, &call.request, &call.response, [this, &call](grpc::Status status) {
      std::lock_guard lock(calls_mutex_);
      call.status = std::move(status);
      call.done = true;
      calls_done_.notify_all();
    });
  }

  // Whether every call started is answered within kPatience.
  bool wait_for_calls() {
    std::unique_lock lock(calls_mutex_);
    return calls_done_.wait_for(lock, kPatience, [&] {
      return std::all_of(calls_.begin(), calls_.end(), [](const auto& call) { return call->done; });
    });
  }
  // Waits for every call and checks call i joined session ids[i].
  void expect_joined(const std::vector<std::string>& ids) {
    ASSERT_TRUE(wait_for_calls()) << "a call was not answered";
    std::lock_guard lock(calls_mutex_);
    ASSERT_EQ(calls_.size(), ids.size());
    for (std::size_t i = 0; i < calls_.size(); ++i) {
      EXPECT_TRUE(calls_[i]->status.ok()) << calls_[i]->status.error_message();
      EXPECT_EQ(calls_[i]->response.session_id(), ids[i]);
    }
  }

  std::filesystem::path dir_;
  std::unique_ptr<FileSessionStore> files_;
  std::unique_ptr<GatedStore> gated_;
  std::unique_ptr<HierarchyCache> cache_;
  std::unique_ptr<SessionRegistry> registry_;
  std::unique_ptr<FiligreeService> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<v1::Filigree::Stub> stub_;
  std::mutex calls_mutex_;
  std::condition_variable calls_done_;
  std::vector<std::unique_ptr<PendingJoin>> calls_;  // calls_mutex_ guards their results
};

TEST_F(SessionLoading, LoadsHeldUpDoNotStopCallsOnSessionsInMemory) {
  // More loads held up at once than gRPC has callback threads (one per core,
  // at least two): before loads left those threads, the third never started.
  const std::size_t held = 2 * std::max(2u, std::thread::hardware_concurrency()) + 2;
  std::vector<std::string> evicted;
  for (std::size_t i = 0; i < held; ++i) evicted.push_back(create_session());
  const std::string in_memory = create_session();
  registry_->evict_idle_until([] { return false; });  // every session leaves memory, records stay
  ASSERT_EQ(registry_->loaded().size(), 0u);
  ASSERT_TRUE(registry_->find(in_memory));  // loaded again while the gate is open

  gated_->close_gate();
  for (const std::string& id : evicted) start_join(id);
  ASSERT_TRUE(gated_->wait_for_waiting(held)) << "only " << gated_->waiting() << " of " << held
                                              << " loads reached the store: loads hold the server's call threads";

  // A call on the session in memory is answered meanwhile.
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + kPatience);
  context.AddMetadata("x-filigree-token", editor_token(in_memory));
  v1::JoinSessionRequest request;
  request.set_session_id(in_memory);
  v1::SessionInfo info;
  const grpc::Status status = stub_->JoinSession(&context, request, &info);
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_EQ(info.session_id(), in_memory);
  {
    std::lock_guard lock(calls_mutex_);
    for (const auto& call : calls_) EXPECT_FALSE(call->done) << "a load finished through a closed gate";
  }

  // The held-up loads finish once the store answers, each with its session.
  gated_->open_gate();
  expect_joined(evicted);
  EXPECT_EQ(registry_->loaded().size(), held + 1);
}

TEST_F(SessionLoading, ADriverOfASessionOutOfMemoryGetsItsFrameOnceItLoads) {
  const std::string id = create_session();
  registry_->evict_idle_until([] { return false; });
  gated_->close_gate();
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + kPatience);
  context.AddMetadata("x-filigree-token", editor_token(id));
  auto stream = stub_->Drive(&context);
  v1::DriveRequest pose;
  pose.set_session_id(id);
  pose.set_pose_id(1);
  pose.add_indices(0);  // base vertex 0 moved
  for (float x : {0.1f, 0.2f, 0.3f}) pose.add_positions(x);
  ASSERT_TRUE(stream->Write(pose));
  ASSERT_TRUE(gated_->wait_for_waiting(1));
  gated_->open_gate();
  // The first frame is the session's current one; the stream's pose comes in a frame after it.
  v1::Frame frame;
  while (stream->Read(&frame) && frame.pose_id() != 1) {
  }
  EXPECT_EQ(frame.pose_id(), 1u);
  stream->WritesDone();
  const grpc::Status status = stream->Finish();
  EXPECT_TRUE(status.ok()) << status.error_message();
}

TEST_F(SessionLoading, AWatcherCancelledWhileItsSessionLoadsLeavesNoSubscription) {
  const std::string id = create_session();
  registry_->evict_idle_until([] { return false; });
  gated_->close_gate();
  grpc::ClientContext context;
  context.AddMetadata("x-filigree-token", editor_token(id));
  v1::WatchRequest request;
  request.set_session_id(id);
  request.set_after_version(1000);  // no frame to write: only the cancel can end the stream
  auto reader = stub_->Watch(&context, request);
  ASSERT_TRUE(gated_->wait_for_waiting(1));
  context.TryCancel();
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  // The load goes on and the session serves others. The stream ends on the
  // server whether the cancel reaches it before the load is done (the start
  // ends it) or after (OnCancel does), and its subscription goes with it.
  gated_->open_gate();
  service_->drain();  // the load's continuation has run
  const auto session = registry_->find(id);
  ASSERT_TRUE(session);
  const auto deadline = std::chrono::steady_clock::now() + kPatience;
  while (session->subscriber_count() > 0 && std::chrono::steady_clock::now() < deadline) std::this_thread::yield();
  EXPECT_EQ(session->subscriber_count(), 0u);
}

class OneLoadAtATime : public SessionLoading {
 protected:
  unsigned session_loads() const override { return 1; }
};

TEST_F(OneLoadAtATime, MoreLoadsWaitTheirTurnOffTheCallThreads) {
  std::vector<std::string> evicted;
  for (int i = 0; i < 3; ++i) evicted.push_back(create_session());
  registry_->evict_idle_until([] { return false; });
  gated_->close_gate();
  for (const std::string& id : evicted) start_join(id);
  ASSERT_TRUE(gated_->wait_for_waiting(1));
  // The other two wait for a turn (a spin on what the service counts, under a deadline: nothing here sleeps).
  const auto deadline = std::chrono::steady_clock::now() + kPatience;
  while (service_->loads_waiting() < 2 && std::chrono::steady_clock::now() < deadline) std::this_thread::yield();
  ASSERT_EQ(service_->loads_waiting(), 2u);
  EXPECT_EQ(gated_->waiting(), 1u);  // the turn holder is the only load at the store

  gated_->open_gate();
  expect_joined(evicted);
}

}  // namespace
}  // namespace filigree::server
