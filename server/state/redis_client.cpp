#include "server/state/redis_client.h"

#include <charconv>

#include "server/state/redis_connection.h"
#include "server/state/session_store.h"

namespace filigree::server {

RedisClient::RedisClient(const std::string& address, std::chrono::milliseconds timeout, RedisCredentials credentials,
                         const RedisTlsOptions& tls)
    : address_(address), host_(address), timeout_(timeout), credentials_(std::move(credentials)) {
  const auto colon = address.rfind(':');
  if (colon != std::string::npos) {
    host_ = address.substr(0, colon);
    const std::string port = address.substr(colon + 1);
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), port_);
    if (ec != std::errc() || end != port.data() + port.size() || port_ <= 0 || port_ > 65535)
      throw StoreUnavailable("Redis address '" + address + "' has no valid port (HOST:PORT)");
  }
  if (host_.empty()) throw StoreUnavailable("Redis address '" + address + "' has no host (HOST:PORT)");
  if (tls.enabled) tls_ = std::make_unique<RedisTls>(tls);
  idle_.push_back(connect());
  command({"PING"});
}

RedisClient::~RedisClient() = default;

RedisClient::Connection RedisClient::connect() {
  auto c = std::make_unique<RedisConnection>(host_, port_, address_, timeout_, tls_.get());
  // AUTH first, on every new connection: Redis refuses anything else until then.
  if (!credentials_.password.empty()) {
    std::vector<std::string_view> args{"AUTH"};
    if (!credentials_.user.empty()) args.push_back(credentials_.user);
    args.push_back(credentials_.password);
    // A broken connection throws here; the connection's messages never quote a command.
    const RedisConnection::Answer answer = c->command(args);
    // Redis' reply (WRONGPASS …) never repeats the password, so it can be quoted.
    if (answer.error)
      throw StoreUnavailable("Redis at " + address_ + " refused authentication" +
                             (credentials_.user.empty() ? std::string() : " as user '" + credentials_.user + "'") +
                             ": " + *answer.error);
  }
  return c;
}

RedisReply RedisClient::command(const std::vector<std::string_view>& args) {
  Connection c;
  {
    std::lock_guard lock(mutex_);
    if (!idle_.empty()) {
      c = std::move(idle_.back());
      idle_.pop_back();
    }
  }
  if (!c) c = connect();
  // A broken (or timed-out) connection throws, and is dropped with `c`.
  RedisConnection::Answer answer = c->command(args);
  {
    std::lock_guard lock(mutex_);
    idle_.push_back(std::move(c));
  }
  if (answer.error) {
    const std::string& message = *answer.error;
    // Redis needs a password this client was not given: say so, not just "NOAUTH".
    if (message.rfind("NOAUTH", 0) == 0)
      throw StoreUnavailable("Redis at " + address_ + " needs authentication" +
                             (credentials_.password.empty() ? " and no password was given" : "") + ": " + message);
    throw StoreUnavailable("Redis at " + address_ + " answered an error: " + message);
  }
  return std::move(answer.reply);
}

RedisReply RedisClient::eval(std::string_view script, const std::vector<std::string_view>& keys,
                             const std::vector<std::string_view>& args) {
  const std::string count = std::to_string(keys.size());
  std::vector<std::string_view> all{"EVAL", script, count};
  all.insert(all.end(), keys.begin(), keys.end());
  all.insert(all.end(), args.begin(), args.end());
  return command(all);
}

}  // namespace filigree::server
