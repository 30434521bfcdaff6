// An existing --data-dir that other users (or the group) can write gets a
// warning at start: session records there hold editor tokens, and hierarchy
// files are loaded in place. A private one gets none. filigree-server runs as
// a child process (started, then stopped with SIGTERM once it listens).

#include <filesystem>
#include <string>

#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "support/server_run.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;

class DataDirWarning : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) / ("filigree_data_dir_" + std::to_string(::getpid()) + "_" +
                                             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  test::ServerRun run_with_mode(mode_t mode) {
    // chmod, not the umask: the mode under test is exactly this one.
    EXPECT_EQ(::chmod(dir_.c_str(), mode), 0);
    return test::run_server(FILIGREE_SERVER_BINARY, {"--data-dir", dir_.string()});
  }

  fs::path dir_;
};

TEST_F(DataDirWarning, AWorldWritableDataDirIsWarnedAboutAtStart) {
  const test::ServerRun run = run_with_mode(0777);
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_NE(run.output.find("level=warning event=data_dir_writable_by_others dir=\"" + dir_.string() + "\" mode=0777 "
                            "writable_by=everyone"),
            std::string::npos)
      << run.output;
}

TEST_F(DataDirWarning, AGroupWritableDataDirIsWarnedAboutToo) {
  const test::ServerRun run = run_with_mode(0770);
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_NE(run.output.find("event=data_dir_writable_by_others dir=\"" + dir_.string() + "\" mode=0770 writable_by=group"),
            std::string::npos)
      << run.output;
}

TEST_F(DataDirWarning, APrivateDataDirIsNot) {
  const test::ServerRun run = run_with_mode(0700);
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_EQ(run.output.find("data_dir_writable_by_others"), std::string::npos) << run.output;
}

}  // namespace
}  // namespace filigree
