#pragma once
// A small, thread-safe Redis client over hiredis: a pool of blocking
// connections on loopback or a LAN, each command on one connection.
// Connection errors and timeouts throw StoreUnavailable; the broken
// connection is dropped and the next command opens a new one.

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <vector>

struct redisContext;

namespace filigree::server {

struct RedisReply {
  enum class Type { kNil, kString, kInteger, kArray, kStatus };
  Type type = Type::kNil;
  std::string str;  // kString, kStatus
  long long integer = 0;
  std::vector<RedisReply> elements;

  bool nil() const { return type == Type::kNil; }
};

class RedisClient {
 public:
  // `address`: "HOST:PORT" or "HOST" (port 6379). Connects at once, so a wrong
  // address fails at start (StoreUnavailable), not at the first request.
  RedisClient(const std::string& address, std::chrono::milliseconds timeout);
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
  struct Free {
    void operator()(redisContext* c) const;
  };
  using Connection = std::unique_ptr<redisContext, Free>;
  Connection connect();

  std::string address_, host_;
  int port_ = 6379;
  std::chrono::milliseconds timeout_;
  std::mutex mutex_;
  std::vector<Connection> idle_;
};

}  // namespace filigree::server
