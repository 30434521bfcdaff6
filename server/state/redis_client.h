#pragma once
// A small, thread-safe Redis client: a pool of blocking connections
// (RedisConnection: plaintext or TLS) on loopback or a LAN, each command on
// one connection. Connection errors and timeouts throw StoreUnavailable; the
// broken connection is dropped and the next command opens a new one. With
// credentials, every new connection sends AUTH before anything else.

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

#include "server/state/redis_reply.h"
#include "server/state/redis_tls.h"

namespace filigree::server {

class RedisConnection;

// How to authenticate to Redis. No password: no AUTH. A password alone:
// AUTH password (requirepass, or the "default" ACL user). A user too: AUTH
// user password (Redis 6 ACL). Error messages name the user, never the password.
struct RedisCredentials {
  std::string user;
  std::string password;
};

class RedisClient {
 public:
  // `address`: "HOST:PORT" or "HOST" (port 6379). Connects (and authenticates)
  // at once, so a wrong address, password or certificate fails at start, not
  // at the first request. A refused AUTH, or a Redis that needs a password when
  // none was given (NOAUTH), throws StoreUnavailable saying so. With
  // `tls.enabled`, every connection is TLS and verifies the server (a
  // certificate it cannot verify throws StoreUnavailable saying why).
  // `timeout` bounds connecting and every wait for Redis.
  RedisClient(const std::string& address, std::chrono::milliseconds timeout, RedisCredentials credentials = {},
              const RedisTlsOptions& tls = {});
  ~RedisClient();
  RedisClient(const RedisClient&) = delete;
  RedisClient& operator=(const RedisClient&) = delete;

  // Runs one command, arguments binary-safe. An error reply throws
  // StoreUnavailable with Redis' message.
  RedisReply command(const std::vector<std::string_view>& args);
  // EVAL of a Lua script with its keys and arguments.
  RedisReply eval(std::string_view script, const std::vector<std::string_view>& keys,
                  const std::vector<std::string_view>& args);

  const std::string& address() const { return address_; }

 private:
  using Connection = std::unique_ptr<RedisConnection>;
  Connection connect();

  std::string address_, host_;
  int port_ = 6379;
  std::chrono::milliseconds timeout_;
  RedisCredentials credentials_;
  std::unique_ptr<RedisTls> tls_;  // null: plaintext
  std::mutex mutex_;
  std::vector<Connection> idle_;
};

}  // namespace filigree::server
