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

}  // namespace

void RedisClient::Free::operator()(redisContext* c) const { redisFree(c); }

RedisClient::RedisClient(const std::string& address, std::chrono::milliseconds timeout)
    : address_(address), host_(address), timeout_(timeout) {
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
  std::vector<const char*> argv;
  std::vector<std::size_t> lengths;
  for (const auto& a : args) argv.push_back(a.data()), lengths.push_back(a.size());
  auto* raw = static_cast<redisReply*>(
      redisCommandArgv(c.get(), static_cast<int>(args.size()), argv.data(), lengths.data()));
  if (!raw) {  // the connection is broken (or timed out): drop it
    throw StoreUnavailable("Redis at " + address_ + " did not answer: " + (c->err ? c->errstr : "no reply"));
  }
  std::unique_ptr<redisReply, void (*)(void*)> reply(raw, freeReplyObject);
  if (reply->type == REDIS_REPLY_ERROR) {
    std::string message(reply->str, reply->len);
    std::lock_guard lock(mutex_);
    idle_.push_back(std::move(c));
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
