// Sessions of one mesh share its immutable data (DESIGN §3.1, issue 10):
// one hierarchy object, one deformer model, one copy of the rest mesh; and
// all of it goes when the last session does. And one frame is shared by its
// subscribers, offered first to the drivers it answers.

#include <algorithm>
#include <condition_variable>
#include <filesystem>
#include <mutex>

#include <grpcpp/impl/codegen/proto_utils.h>
#include <gtest/gtest.h>

#include "hierarchy/hierarchy.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer_model.h"
#include "server/hierarchy_cache.h"
#include "server/secret.h"
#include "server/session_assets.h"
#include "server/session_registry.h"
#include "server/state/file_session_store.h"
#include "support/test_meshes.h"

namespace filigree::server {
namespace {

class SessionSharing : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("filigree_sharing_" + random_token());
    std::filesystem::create_directories(dir_);
    store_ = std::make_unique<FileSessionStore>(dir_ / "sessions");
    cache_ = std::make_unique<HierarchyCache>(dir_ / "hierarchies");
    registry_ = std::make_unique<SessionRegistry>(*cache_, *store_, RegistryLimits{});
  }
  void TearDown() override {
    registry_.reset();
    std::filesystem::remove_all(dir_);
  }
  std::shared_ptr<const Hierarchy> hierarchy_of(const TriMesh& mesh, std::string& key) {
    PreprocessOptions o;
    o.base_vertices = 60;
    return cache_->get_or_build(mesh, o, &key, nullptr);
  }

  std::filesystem::path dir_;
  std::unique_ptr<FileSessionStore> store_;
  std::unique_ptr<HierarchyCache> cache_;
  std::unique_ptr<SessionRegistry> registry_;
};

TEST_F(SessionSharing, TwoSessionsOfOneMeshShareOneHierarchyAndModel) {
  std::string key;
  auto h = hierarchy_of(test::icosphere(3), key);
  auto a = registry_->create(h, key, {}, {});
  std::string key2;
  auto again = hierarchy_of(test::icosphere(3), key2);  // the same mesh uploaded again
  auto b = registry_->create(again, key2, {}, {});
  EXPECT_EQ(key, key2);
  EXPECT_EQ(h.get(), again.get());
  EXPECT_EQ(&a->assets(), &b->assets());
  EXPECT_EQ(&a->assets().hierarchy(), h.get());
  EXPECT_EQ(a->assets().model.get(), b->assets().model.get());
  EXPECT_EQ(registry_->live_meshes(), 1u);

  // Another mesh gets its own.
  std::string other_key;
  auto c = registry_->create(hierarchy_of(test::torus(24, 12), other_key), other_key, {}, {});
  EXPECT_NE(&c->assets(), &a->assets());
  EXPECT_EQ(registry_->live_meshes(), 2u);
}

TEST_F(SessionSharing, InfoWireNamesTheVersionItIsGivenAndOtherwiseIsTheTypedInfo) {
  // SetOptions answers with the version at which the change was accepted,
  // not the current one: info_wire(v) must carry v, and the rest as info().
  // With uploaded ids, so that the wire's cached id field must be the right one.
  std::string key;
  auto s = registry_->create(hierarchy_of(test::icosphere(3), key), key, {}, {2, 0, 1});
  grpc::ByteBuffer wire = s->info_wire(SIZE_MAX, 42);
  v1::SessionInfo parsed;
  ASSERT_TRUE(grpc::SerializationTraits<v1::SessionInfo>::Deserialize(&wire, &parsed).ok());
  EXPECT_EQ(parsed.version(), 42u);
  EXPECT_EQ(parsed.rest().uploaded_ids_size(), 3);
  v1::SessionInfo typed = s->info(SIZE_MAX);
  EXPECT_NE(typed.version(), 42u);
  typed.set_version(42);
  EXPECT_EQ(parsed.SerializeAsString(), typed.SerializeAsString());
}

TEST_F(SessionSharing, ASmallMeshsFramesAreSplitForEveryFrameThread) {
  // 10242 vertices, under 2 · 2 chunks of 16384: with two frame threads its
  // frames come in 4 even chunks (two per thread), with one in 2.
  std::string key;
  auto h = hierarchy_of(test::icosphere(5), key);
  ASSERT_EQ(h->vertex_count(), 10242u);
  for (const unsigned threads : {2u, 1u}) {
    RegistryLimits limits;
    limits.frame_threads = threads;
    SessionRegistry registry(*cache_, *store_, limits);
    const auto s = registry.create(h, key, {}, {});
    const v1::Frame& frame = s->current_frame()->frame;
    ASSERT_EQ(frame.chunks_size(), static_cast<int>(2 * threads)) << threads << " threads";
    const std::uint32_t size = (10242u + 2 * threads - 1) / (2 * threads);
    for (int k = 0; k < frame.chunks_size(); ++k) {
      EXPECT_EQ(frame.chunks(k).first_vertex(), k * size);
      EXPECT_EQ(frame.chunks(k).vertex_count(), std::min(size, 10242u - k * size)) << "chunk " << k;
    }
    registry.close(s->id());
  }
}

TEST_F(SessionSharing, HierarchyIsFreedWhenItsLastSessionCloses) {
  std::string key;
  std::weak_ptr<const Hierarchy> watch;
  std::string first, second;
  {
    auto h = hierarchy_of(test::icosphere(3), key);
    watch = h;
    first = registry_->create(h, key, {}, {})->id();
    second = registry_->create(h, key, {}, {})->id();
  }
  ASSERT_FALSE(watch.expired()) << "sessions hold the hierarchy";
  ASSERT_TRUE(registry_->close(first));
  EXPECT_FALSE(watch.expired()) << "one session is left";
  ASSERT_TRUE(registry_->close(second));
  EXPECT_TRUE(watch.expired()) << "the last session is gone: the hierarchy must be freed";
  EXPECT_EQ(registry_->live_meshes(), 0u);
  // And a new upload of the same mesh still works (loaded from disk).
  auto h = hierarchy_of(test::icosphere(3), key);
  EXPECT_TRUE(registry_->create(h, key, {}, {}) != nullptr);
}

// A sink that remembers how it was closed.
struct RecordingSink : FrameSink {
  void offer(std::shared_ptr<const PublishedFrame>) override {}
  v1::FrameFormat format() const override { return v1::FRAME_FORMAT_CHUNKED; }
  void close(bool session_closed, const std::string& why) override {
    closed = true;
    as_session_closed = session_closed;
    reason = why;
  }
  bool closed = false, as_session_closed = false;
  std::string reason;
};

TEST_F(SessionSharing, AnEvictedSessionRefusesChangesInsteadOfLosingThemAndLoadsAgain) {
  std::string key;
  auto h = hierarchy_of(test::icosphere(3), key);
  auto s = registry_->create(h, key, {}, {});
  const std::vector<std::uint32_t> index{0};
  const std::vector<float> moved{0.5f, 0.25f, -0.125f};
  s->submit({0, "before", 1, false}, index, moved);

  // In use: not evicted.
  auto watcher = std::make_shared<RecordingSink>();
  s->subscribe(watcher, std::nullopt);
  EXPECT_FALSE(s->evict_if_unused());
  s->unsubscribe(watcher.get());

  // Unused: evicted in one step; a request that still holds it is refused.
  EXPECT_EQ(registry_->evict_idle_until([] { return false; }), 1u);
  EXPECT_THROW(s->submit({0, "late", 2, false}, index, moved), StoreUnavailable);
  auto late = std::make_shared<RecordingSink>();
  s->subscribe(late, std::nullopt);
  EXPECT_TRUE(late->closed);
  EXPECT_FALSE(late->as_session_closed) << "an evicted session is not closed for good: reconnect";
  EXPECT_TRUE(registry_->loaded().empty());

  // Its record brings it back, with the pose merged before eviction.
  auto again = registry_->find(s->id());
  ASSERT_TRUE(again != nullptr);
  EXPECT_NE(again.get(), s.get());
  grpc::ByteBuffer wire = again->state_wire(v1::FRAME_FORMAT_CHUNKED);
  v1::SessionState state;
  ASSERT_TRUE(grpc::SerializationTraits<v1::SessionState>::Deserialize(&wire, &state).ok());
  ASSERT_GE(state.pose_size(), 3);
  EXPECT_EQ(state.pose(0), 0.5f);
  EXPECT_EQ(state.pose(1), 0.25f);
  EXPECT_EQ(state.pose(2), -0.125f);
}

// Waits (on the session's own signal, no sleeping) for a frame newer than `after`.
struct VersionSink : FrameSink {
  void offer(std::shared_ptr<const PublishedFrame> frame) override {
    std::lock_guard lock(mutex);
    latest = std::max(latest, frame->frame.version());
    changed.notify_all();
  }
  v1::FrameFormat format() const override { return v1::FRAME_FORMAT_CHUNKED; }
  void close(bool, const std::string&) override {}
  void wait_past(std::uint64_t after) {
    std::unique_lock lock(mutex);
    changed.wait(lock, [&] { return latest > after; });
  }
  std::mutex mutex;
  std::condition_variable changed;
  std::uint64_t latest = 0;
};

TEST_F(SessionSharing, IdleSessionsHoldNoFrameBufferAndShareOneThatGoesRound) {
  // A session needs its frame positions only from computing a frame to
  // quantizing it; the rest of the time they are in the mesh's pool, so a
  // further idle session costs no frame buffer (issue 10: ≤ 64 B/vertex).
  std::string key;
  auto h = hierarchy_of(test::icosphere(3), key);
  auto a = registry_->create(h, key, {}, {});
  auto b = registry_->create(h, key, {}, {});
  const BufferPool<Vec3>& frames = *a->assets().frames;
  EXPECT_EQ(frames.free_buffers(), 1u) << "both initial frames used the same buffer, now free";
  const std::vector<std::uint32_t> index{0};
  for (int round = 1; round <= 3; ++round)
    for (const auto& s : {a, b}) {
      auto sink = std::make_shared<VersionSink>();
      s->subscribe(sink, std::nullopt);
      const std::uint64_t before = s->version();
      const std::vector<float> moved{0.1f * static_cast<float>(round), 0.2f, -0.1f};
      s->submit({0, "editor", static_cast<std::uint64_t>(round), false}, index, moved);
      sink->wait_past(before);
      s->unsubscribe(sink.get());
      EXPECT_EQ(frames.free_buffers(), 1u) << "round " << round << ": the frame buffer went back";
    }
}

// Records the order in which sinks are offered frame `version`.
struct OrderSink : VersionSink {
  OrderSink(std::uint64_t driver_id, std::vector<std::uint64_t>& log, std::mutex& log_mutex)
      : id(driver_id), order(log), order_mutex(log_mutex) {}
  void offer(std::shared_ptr<const PublishedFrame> frame) override {
    {
      std::lock_guard lock(order_mutex);
      if (frame->pose_of_driver.count(7)) order.push_back(id);
    }
    VersionSink::offer(frame);
  }
  std::uint64_t driver() const override { return id; }
  const std::uint64_t id;  // 0: a watcher
  std::vector<std::uint64_t>& order;
  std::mutex& order_mutex;
};

TEST_F(SessionSharing, AFrameGoesFirstToTheDriverWhosePoseItAnswers) {
  // Offering a frame starts the stream's write (the frame into its socket),
  // so the driver waiting for its pose goes before the watchers, whatever
  // the order they subscribed in.
  std::string key;
  auto h = hierarchy_of(test::icosphere(3), key);
  auto s = registry_->create(h, key, {}, {});
  std::vector<std::uint64_t> order;
  std::mutex order_mutex;
  auto first_watcher = std::make_shared<OrderSink>(0, order, order_mutex);
  auto driver = std::make_shared<OrderSink>(7, order, order_mutex);
  auto last_watcher = std::make_shared<OrderSink>(0, order, order_mutex);
  for (const auto& sink : {first_watcher, driver, last_watcher}) s->subscribe(sink, s->version());
  const std::uint64_t before = s->version();
  const std::vector<std::uint32_t> index{0};
  const std::vector<float> moved{0.3f, 0.2f, -0.1f};
  s->submit({7, "editor", 1, false}, index, moved);
  // Both watchers offered: every offer is in the log (the driver's, if it
  // came last, may not be, and the check below then fails).
  first_watcher->wait_past(before);
  last_watcher->wait_past(before);
  std::lock_guard lock(order_mutex);
  ASSERT_GE(order.size(), 3u);
  EXPECT_EQ(order[0], 7u) << "the driver's frame went out after a watcher's";
  EXPECT_EQ(order[1], 0u);
  EXPECT_EQ(order[2], 0u);
}

}  // namespace
}  // namespace filigree::server
