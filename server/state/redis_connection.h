#pragma once
// One connection to Redis over TCP, plaintext or TLS. hiredis still speaks
// the protocol (it formats the commands and parses the replies), but the bytes
// travel through this class' own transport: Debian's hiredis 0.14 has no TLS.
// Every wait (connect, handshake, send, receive) is bounded by the timeout,
// so a silent or wrong peer fails a command instead of hanging it.

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "server/state/redis_reply.h"

struct redisReader;

namespace filigree::server {

class RedisTls;
class RedisTransport;  // plaintext or TLS bytes over the socket (redis_connection.cpp)

class RedisConnection {
 public:
  // What Redis answered to a command: a reply, or the message of its error reply.
  struct Answer {
    RedisReply reply;
    std::optional<std::string> error;
  };

  // Connects to `host`:`port`; with `tls`, also does the TLS handshake,
  // verifying the server's certificate and name. `address` names Redis in
  // messages. Throws StoreUnavailable saying what failed.
  RedisConnection(const std::string& host, int port, const std::string& address, std::chrono::milliseconds timeout,
                  const RedisTls* tls);
  ~RedisConnection();
  RedisConnection(const RedisConnection&) = delete;
  RedisConnection& operator=(const RedisConnection&) = delete;

  // Sends one command, arguments binary-safe, and reads its reply. Throws
  // StoreUnavailable if the connection breaks, a wait times out or Redis'
  // bytes are not a reply; the connection is then unusable (drop it).
  Answer command(const std::vector<std::string_view>& args);

 private:
  std::string closed_message() const;

  std::string address_;
  bool tls_ = false;
  bool answered_ = false;  // no reply yet: a refusal is more likely a wrong transport than a restart
  std::unique_ptr<RedisTransport> transport_;
  redisReader* reader_ = nullptr;
  std::vector<char> buffer_;
};

}  // namespace filigree::server
