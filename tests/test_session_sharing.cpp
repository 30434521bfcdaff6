// Sessions of one mesh share its immutable data (DESIGN §3.1, issue 10):
// one hierarchy object, one deformer model, one copy of the rest mesh; and
// all of it goes when the last session does.

#include <filesystem>

#include <gtest/gtest.h>

#include "hierarchy/hierarchy.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer_model.h"
#include "server/hierarchy_cache.h"
#include "server/secret.h"
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

}  // namespace
}  // namespace filigree::server
