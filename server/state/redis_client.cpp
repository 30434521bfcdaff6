#include "server/state/redis_client.h"

#include <charconv>

#include <hiredis/hiredis.h>

#include "server/state/session_store.h"

namespace filigree::server {
namespace {

timeval to_timeval(std::chrono::milliseconds ms) {
  return {static_cast<time_t>(ms.count() / 1000), static_cast<suseconds_t>((ms.count() % 1000) * 1000)};
}

RedisReply convert(const redisReply& r) {
  RedisReply out;
  switch (r.type) {
    case REDIS_REPLY_STRING:
      out.type = RedisReply::Type::kString;
      out.str.assign(r.str, r.len);
      break;
    case REDIS_REPLY_STATUS:
      out.type = RedisReply::Type::kStatus;
      out.str.assign(r.str, r.len);
      break;
    case REDIS_REPLY_INTEGER:
      out.type = RedisReply::Type::kInteger;
      out.integer = r.integer;
      break;
    case REDIS_REPLY_ARRAY:
      out.type = RedisReply::Type::kArray;
      for (std::size_t i = 0; i < r.elements; ++i) out.elements.push_back(convert(*r.element[i]));
      break;
    default:
      break;
  }
  return out;
}

using ReplyPtr = std::unique_ptr<redisReply, void (*)(void*)>;

// Sends one command, arguments binary-safe; the reply, or null if the
// connection broke or timed out (c->errstr says why).
ReplyPtr send_command(redisContext* c, const std::vector<std::string_view>& args) {
  std::vector<const char*> argv;
  std::vector<std::size_t> lengths;
  for (const auto& a : args) argv.push_back(a.data()), lengths.push_back(a.size());
  return ReplyPtr(static_cast<redisReply*>(redisCommandArgv(c, static_cast<int>(args.size()), argv.data(), lengths.data())),
                  freeReplyObject);
}

}  // namespace

void RedisClient::Free::operator()(redisContext* c) const { redisFree(c); }

RedisClient::RedisClient(const std::string& address, std::chrono::milliseconds timeout, RedisCredentials credentials)
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
  idle_.push_back(connect());
  command({"PING"});
}

RedisClient::~RedisClient() = default;

RedisClient::Connection RedisClient::connect() {
  Connection c(redisConnectWithTimeout(host_.c_str(), port_, to_timeval(timeout_)));
  if (!c) throw StoreUnavailable("cannot allocate a Redis connection");
  if (c->err) throw StoreUnavailable("cannot connect to Redis at " + address_ + ": " + c->errstr);
  redisSetTimeout(c.get(), to_timeval(timeout_));
  redisEnableKeepAlive(c.get());
  // AUTH first, on every new connection: Redis refuses anything else until then.
  if (!credentials_.password.empty()) {
    std::vector<std::string_view> args{"AUTH"};
    if (!credentials_.user.empty()) args.push_back(credentials_.user);
    args.push_back(credentials_.password);
    const ReplyPtr reply = send_command(c.get(), args);
    if (!reply) throw StoreUnavailable("Redis at " + address_ + " did not answer AUTH: " + (c->err ? c->errstr : "no reply"));
    // Redis' reply (WRONGPASS …) never repeats the password, so it can be quoted.
    if (reply->type == REDIS_REPLY_ERROR)
      throw StoreUnavailable("Redis at " + address_ + " refused authentication" +
                             (credentials_.user.empty() ? std::string() : " as user '" + credentials_.user + "'") +
                             ": " + std::string(reply->str, reply->len));
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
  const ReplyPtr reply = send_command(c.get(), args);
  if (!reply) {  // the connection is broken (or timed out): drop it
    throw StoreUnavailable("Redis at " + address_ + " did not answer: " + (c->err ? c->errstr : "no reply"));
  }
  if (reply->type == REDIS_REPLY_ERROR) {
    std::string message(reply->str, reply->len);
    std::lock_guard lock(mutex_);
    idle_.push_back(std::move(c));
    // Redis needs a password this client was not given: say so, not just "NOAUTH".
    if (message.rfind("NOAUTH", 0) == 0)
      throw StoreUnavailable("Redis at " + address_ + " needs authentication" +
                             (credentials_.password.empty() ? " and no password was given" : "") + ": " + message);
    throw StoreUnavailable("Redis at " + address_ + " answered an error: " + message);
  }
  RedisReply out = convert(*reply);
  std::lock_guard lock(mutex_);
  idle_.push_back(std::move(c));
  return out;
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
