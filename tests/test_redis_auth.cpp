// Redis AUTH for the shared store: RedisClient and filigree-server against a
// redis-server started here, its passwords made up at run time and kept in
// its configuration file (never on a command line, never in the repository).

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "filigree/client.h"
#include "server/state/redis_client.h"
#include "server/state/session_store.h"
#include "support/store_errors.h"
#include "support/child_process.h"
#include "support/server_process.h"
#include "support/server_run.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;
using server::RedisClient;
using server::RedisCredentials;
using server::StoreUnavailable;

constexpr std::chrono::milliseconds kTimeout(2000);

using test::random_password;
using test::store_error;

using test::ServerRun;

ServerRun run_server(const std::vector<std::string>& args, const std::vector<std::string>& env = {}) {
  return test::run_server(FILIGREE_SERVER_BINARY, args, env);
}

// A redis-server on 127.0.0.1 needing a password (requirepass) with also an
// ACL user, both in its configuration file in a temporary directory.
class RedisAuth : public ::testing::Test {
 protected:
  RedisAuth() {
    char tmpl[] = "/tmp/filigree-redis-auth-XXXXXX";
    if (!mkdtemp(tmpl)) throw std::runtime_error("mkdtemp failed");
    dir_ = tmpl;
    const int port = test::free_port();
    address_ = "127.0.0.1:" + std::to_string(port);
    const fs::path conf = dir_ / "redis.conf";
    write_private(conf, "bind 127.0.0.1\nport " + std::to_string(port) + "\nsave \"\"\nappendonly no\ndir " +
                            dir_.string() + "\nrequirepass " + password_ + "\nuser " + user_ + " on >" +
                            user_password_ + " ~* +@all\n");
    redis_ = std::make_unique<test::ChildProcess>(std::vector<std::string>{"redis-server", conf.string()},
                                                  (dir_ / "redis.log").string());
    redis_->wait_for_port(port, 20);
  }
  ~RedisAuth() override {
    redis_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  // Writes `text` to `file`, readable by this user only (as a secret should be).
  static void write_private(const fs::path& file, const std::string& text) {
    std::ofstream(file) << text;
    fs::permissions(file, fs::perms::owner_read | fs::perms::owner_write);
  }
  // A password file holding `text`.
  std::string password_file(const std::string& text) const {
    const fs::path file = dir_ / "password";
    write_private(file, text);
    return file.string();
  }

  fs::path dir_;
  std::string address_;
  const std::string password_ = random_password(), user_ = "filigree", user_password_ = random_password();
  std::unique_ptr<test::ChildProcess> redis_;
};

TEST_F(RedisAuth, TheRightPasswordOrAclUserCanSetAndGet) {
  RedisClient with_password(address_, kTimeout, {"", password_});
  with_password.command({"SET", "k", "v"});
  EXPECT_EQ(with_password.command({"GET", "k"}).str, "v");
  RedisClient as_user(address_, kTimeout, {user_, user_password_});
  EXPECT_EQ(as_user.command({"GET", "k"}).str, "v");
}

TEST_F(RedisAuth, NoPasswordFailsSayingRedisNeedsOne) {
  const std::string message = store_error([&] { RedisClient c(address_, kTimeout); });
  EXPECT_NE(message.find("needs authentication and no password was given"), std::string::npos) << message;
  EXPECT_EQ(message.find(password_), std::string::npos) << message;
}

TEST_F(RedisAuth, AWrongPasswordOrUserFailsWithoutShowingThePassword) {
  const std::string wrong = random_password();
  const std::string message = store_error([&] { RedisClient c(address_, kTimeout, {"", wrong}); });
  EXPECT_NE(message.find("refused authentication"), std::string::npos) << message;
  EXPECT_EQ(message.find(wrong), std::string::npos) << message;
  EXPECT_EQ(message.find(password_), std::string::npos) << message;
  // Another user's password is wrong too.
  const std::string as_user = store_error([&] { RedisClient c(address_, kTimeout, {user_, password_}); });
  EXPECT_NE(as_user.find("refused authentication as user 'filigree'"), std::string::npos) << as_user;
  EXPECT_EQ(as_user.find(password_), std::string::npos) << as_user;
}

TEST_F(RedisAuth, ANewConnectionAuthenticatesBeforeItsFirstCommand) {
  RedisClient client(address_, kTimeout, {"", password_}), admin(address_, kTimeout, {"", password_});
  // Redis drops every other client's connection (not admin's own).
  admin.command({"CLIENT", "KILL", "TYPE", "normal"});
  // The broken connection fails the next command and is dropped; the one after reconnects.
  EXPECT_THROW(client.command({"SET", "k", "before"}), StoreUnavailable);
  client.command({"SET", "k", "after"});
  EXPECT_EQ(admin.command({"GET", "k"}).str, "after");
}

TEST_F(RedisAuth, ServerWithThePasswordFileStartsAndKeepsSessionsInRedis) {
  // Trailing whitespace (an editor's newline, CRLF) is not part of the password.
  test::ServerProcess server(FILIGREE_SERVER_BINARY, {"--redis", address_, "--redis-password-file",
                                                      password_file(password_ + " \r\nsecond line\n"),
                                                      "--data-dir", (dir_ / "data").string()});
  const SessionHandle s = Client(server.address())
                              .create_session(test::file_bytes(test::shipped_path("bunny_small.obj")), "obj", {}, "auth");
  RedisClient redis(address_, kTimeout, {"", password_});
  EXPECT_EQ(redis.command({"EXISTS", "filigree:session:" + s.session_id}).integer, 1);
  EXPECT_EQ(server.terminate(), 0);
}

TEST_F(RedisAuth, ServerTakesThePasswordFromTheEnvironmentWithoutAFile) {
  const ServerRun run = run_server({"--redis", address_}, {"FILIGREE_REDIS_PASSWORD=" + password_});
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_EQ(run.status, 0) << run.output;
  EXPECT_NE(run.output.find("redis_auth=password"), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find(password_), std::string::npos) << run.output;
  // A file wins over the environment.
  const ServerRun file = run_server({"--redis", address_, "--redis-password-file", password_file(password_)},
                              {"FILIGREE_REDIS_PASSWORD=" + random_password()});
  EXPECT_TRUE(file.listened) << file.output;
}

TEST_F(RedisAuth, ServerAuthenticatesAsAnAclUser) {
  const ServerRun run = run_server(
      {"--redis", address_, "--redis-user", user_, "--redis-password-file", password_file(user_password_)});
  EXPECT_TRUE(run.listened) << run.output;
  EXPECT_NE(run.output.find("redis_auth=user:filigree"), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find(user_password_), std::string::npos) << run.output;
}

// As when Redis cannot be reached: the server does not start, and says why.
TEST_F(RedisAuth, ServerWithAWrongOrNoPasswordExitsSayingWhy) {
  const std::string wrong = random_password();
  const ServerRun bad = run_server({"--redis", address_, "--redis-password-file", password_file(wrong)});
  EXPECT_FALSE(bad.listened);
  EXPECT_EQ(bad.status, 1) << bad.output;
  EXPECT_NE(bad.output.find("event=fatal"), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("refused authentication"), std::string::npos) << bad.output;
  EXPECT_EQ(bad.output.find(wrong), std::string::npos) << bad.output;

  const ServerRun none = run_server({"--redis", address_});
  EXPECT_FALSE(none.listened);
  EXPECT_EQ(none.status, 1) << none.output;
  EXPECT_NE(none.output.find("needs authentication and no password was given"), std::string::npos) << none.output;

  const ServerRun missing = run_server({"--redis", address_, "--redis-password-file", (dir_ / "absent").string()});
  EXPECT_EQ(missing.status, 1) << missing.output;
  EXPECT_NE(missing.output.find("cannot read --redis-password-file"), std::string::npos) << missing.output;
  const ServerRun empty = run_server({"--redis", address_, "--redis-password-file", password_file(" \n")});
  EXPECT_EQ(empty.status, 1) << empty.output;
  EXPECT_NE(empty.output.find("has no password on its first line"), std::string::npos) << empty.output;
}

// A password on the command line would be visible to every user (ps): there is no such option.
TEST_F(RedisAuth, ServerHasNoPasswordOption) {
  const ServerRun run = run_server({"--redis", address_, "--redis-password", "unused"});
  EXPECT_FALSE(run.listened);
  EXPECT_NE(run.status, 0) << run.output;
  // Refused as an unknown option, not by Redis after using it.
  EXPECT_NE(run.output.find("were not expected"), std::string::npos) << run.output;
  EXPECT_EQ(run.output.find("event=fatal"), std::string::npos) << run.output;
}

}  // namespace
}  // namespace filigree
