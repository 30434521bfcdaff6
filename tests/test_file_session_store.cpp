// Session records on one machine (server/state/file_session_store.h): what a
// running session changes is written apart from the record it was created
// with, and a load puts them back together; stale or corrupt files are
// handled, never crash.

#include <filesystem>
#include <fstream>
#include <memory>
#include <numeric>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "server/secret.h"
#include "server/state/file_session_store.h"

namespace filigree::server {
namespace {

std::string bytes_of(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

constexpr const char* kId = "0123456789abcdef0123";

class FileSessionStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() / ("filigree_store_" + random_token());
    store_ = std::make_unique<FileSessionStore>(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // A record as a 100k-vertex upload leaves it: its ids dominate its size.
  static SessionRecord created() {
    SessionRecord r;
    r.id = kId;
    r.hierarchy_key = "abc";
    r.editor_token.assign(32, 'e');
    r.viewer_token.assign(32, 'v');
    r.pose = {1.0f, 2.0f, 3.0f};
    r.version = 1;
    r.uploaded_ids.resize(100000);
    std::iota(r.uploaded_ids.rbegin(), r.uploaded_ids.rend(), 0u);
    return r;
  }
  static SessionProgress progress(std::uint64_t version) {
    SessionProgress p;
    p.options.set_threshold(5e3);
    p.pose = {4.0f, 5.0f, static_cast<float>(version)};
    p.version = version;
    p.handles = {{42, "alice", {0.5f, 1.5f, 2.5f}}};
    p.cut.unrecovered = {3, 9};
    p.cut.scores = {0.5f, 0.0f, 2.0f};
    return p;
  }
  std::filesystem::path file(const char* extension) const { return dir_ / (std::string(kId) + extension); }

  std::filesystem::path dir_;
  std::unique_ptr<FileSessionStore> store_;
};

TEST_F(FileSessionStoreTest, ProgressIsWrittenApartAndAppliedOnLoad) {
  const SessionRecord r = created();
  ASSERT_TRUE(store_->create(r));
  const std::string record_bytes = bytes_of(file(".session"));
  ASSERT_TRUE(store_->save_progress(r.id, progress(8)));
  // The record as created is not rewritten; the progress is a small file.
  EXPECT_EQ(bytes_of(file(".session")), record_bytes);
  EXPECT_LT(std::filesystem::file_size(file(".progress")) * 100, record_bytes.size());
  const std::optional<SessionRecord> back = store_->load(r.id);
  ASSERT_TRUE(back);
  EXPECT_EQ(back->version, 8u);
  EXPECT_EQ(back->pose, progress(8).pose);
  EXPECT_EQ(back->options.threshold(), 5e3);
  EXPECT_EQ(back->handles, progress(8).handles);
  EXPECT_EQ(back->cut.unrecovered, progress(8).cut.unrecovered);
  EXPECT_EQ(back->uploaded_ids, r.uploaded_ids);
  EXPECT_EQ(back->editor_token, r.editor_token);
  // Newer progress replaces the older.
  ASSERT_TRUE(store_->save_progress(r.id, progress(9)));
  EXPECT_EQ(store_->load(r.id)->pose, progress(9).pose);
  EXPECT_EQ(store_->list(), std::vector<std::string>{r.id});
}

TEST_F(FileSessionStoreTest, AWholeRecordSupersedesOlderProgress) {
  SessionRecord r = created();
  ASSERT_TRUE(store_->create(r));
  ASSERT_TRUE(store_->save_progress(r.id, progress(5)));
  r.version = 10;
  r.pose = {7.0f, 7.0f, 7.0f};
  ASSERT_TRUE(store_->save(r));
  EXPECT_FALSE(std::filesystem::exists(file(".progress")));
  EXPECT_EQ(store_->load(r.id)->version, 10u);
  // Progress older than the record (as a crash between the record's write
  // and the old progress's removal leaves it) is ignored.
  ASSERT_TRUE(store_->save_progress(r.id, progress(6)));
  const std::optional<SessionRecord> back = store_->load(r.id);
  EXPECT_EQ(back->version, 10u);
  EXPECT_EQ(back->pose, r.pose);
}

// Records hold the session's tokens: only the server's user may read them.
TEST_F(FileSessionStoreTest, RecordsAndProgressAreOwnerOnly) {
  const SessionRecord r = created();
  ASSERT_TRUE(store_->create(r));
  ASSERT_TRUE(store_->save_progress(r.id, progress(3)));
  EXPECT_EQ(std::filesystem::status(dir_).permissions() & std::filesystem::perms::all, std::filesystem::perms::owner_all)
      << "the folder the store made";
  for (const char* ext : {".session", ".progress"}) {
    const auto perms = std::filesystem::status(file(ext)).permissions();
    EXPECT_EQ(perms & (std::filesystem::perms::group_all | std::filesystem::perms::others_all), std::filesystem::perms::none)
        << ext;
  }
}

TEST_F(FileSessionStoreTest, CorruptProgressIsAClearErrorAndUnknownSessionsHaveNone) {
  const SessionRecord r = created();
  ASSERT_TRUE(store_->create(r));
  std::ofstream(file(".progress"), std::ios::binary) << "not a progress record";
  try {
    store_->load(r.id);
    FAIL() << "a corrupt progress file loaded";
  } catch (const SessionUnusable& e) {
    // Which session, not where it is stored: the message reaches clients.
    EXPECT_NE(std::string(e.what()).find("stored progress of session " + r.id + " is unreadable"), std::string::npos)
        << e.what();
    EXPECT_EQ(std::string(e.what()).find(dir_.string()), std::string::npos) << e.what();
  }
  // Progress of a session with no record is refused, and writes nothing.
  const std::string other = "fedcba9876543210fedc";
  EXPECT_FALSE(store_->save_progress(other, progress(2)));
  EXPECT_FALSE(std::filesystem::exists(dir_ / (other + ".progress")));
  EXPECT_FALSE(store_->load(other));
  // Removing a session removes both files.
  store_->remove(r.id);
  EXPECT_FALSE(std::filesystem::exists(file(".session")));
  EXPECT_FALSE(std::filesystem::exists(file(".progress")));
  EXPECT_TRUE(store_->list().empty());
}

}  // namespace
}  // namespace filigree::server
