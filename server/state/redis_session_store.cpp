#include "server/state/redis_session_store.h"

#include "server/state/redis_client.h"

namespace filigree::server {
namespace {

// KEYS: lease, session. ARGV: replica, record, lease ms.
constexpr std::string_view kCreate = R"(
if redis.call('EXISTS', KEYS[2]) == 1 then return 0 end
redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[3])
redis.call('SET', KEYS[2], ARGV[2])
return 1)";

// KEYS: lease, state. ARGV: replica, progress. Fenced by the lease.
constexpr std::string_view kSave = R"(
if redis.call('GET', KEYS[1]) ~= ARGV[1] then return 0 end
redis.call('SET', KEYS[2], ARGV[2])
return 1)";

// KEYS: lease, handoff. ARGV: replica, lease ms, take over (0/1).
// → {1, replica, 0} when acquired, else {0, owner, ms left}.
constexpr std::string_view kClaim = R"(
local owner = redis.call('GET', KEYS[1])
if not owner or owner == ARGV[1] then
  redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[2])
  if redis.call('GET', KEYS[2]) == ARGV[1] then redis.call('DEL', KEYS[2]) end
  return {1, ARGV[1], 0}
end
if ARGV[3] == '1' then redis.call('SET', KEYS[2], ARGV[1], 'PX', ARGV[2]) end
return {0, owner, redis.call('PTTL', KEYS[1])})";

// KEYS: lease, handoff. ARGV: replica, lease ms, may hand off (0/1).
// → 1 held (extended), 0 lost, 2 another replica asks for it.
constexpr std::string_view kRenew = R"(
if redis.call('GET', KEYS[1]) ~= ARGV[1] then return 0 end
local asker = redis.call('GET', KEYS[2])
if asker and asker ~= ARGV[1] and ARGV[3] == '1' then return 2 end
redis.call('PEXPIRE', KEYS[1], ARGV[2])
return 1)";

// KEYS: lease. ARGV: replica.
constexpr std::string_view kRelease = R"(
if redis.call('GET', KEYS[1]) == ARGV[1] then redis.call('DEL', KEYS[1]) end
return 1)";

}  // namespace

RedisSessionStore::RedisSessionStore(std::shared_ptr<RedisClient> redis, RedisSessionStoreOptions options)
    : redis_(std::move(redis)),
      options_(std::move(options)),
      advertise_(options_.advertise),
      lease_ms_(std::to_string(options_.lease.count())) {
  if (options_.replica_id.empty()) throw std::invalid_argument("a replica needs an id");
  heartbeat();
}

void RedisSessionStore::set_advertise(std::string address) {
  {
    std::lock_guard lock(advertise_mutex_);
    advertise_ = std::move(address);
  }
  heartbeat();
}

bool RedisSessionStore::create(const SessionRecord& r) {
  const std::string lease = key("lease:", r.id), session = key("session:", r.id), bytes = encode_session_record(r);
  return redis_->eval(kCreate, {lease, session}, {options_.replica_id, bytes, lease_ms_}).integer == 1;
}

bool RedisSessionStore::save(const SessionRecord& r) { return save_progress(r.id, progress_of(r)); }

bool RedisSessionStore::save_progress(const std::string& id, const SessionProgress& p) {
  const std::string lease = key("lease:", id), state = key("state:", id), bytes = encode_session_progress(p);
  return redis_->eval(kSave, {lease, state}, {options_.replica_id, bytes}).integer == 1;
}

bool RedisSessionStore::save_history(const std::string& id, const std::string& bytes) {
  // Only by the lease's holder, like progress.
  return redis_->eval(kSave, {key("lease:", id), key("history:", id)}, {options_.replica_id, bytes}).integer == 1;
}

std::optional<SessionRecord> RedisSessionStore::load(const std::string& id) {
  const RedisReply reply = redis_->command({"MGET", key("session:", id), key("state:", id), key("history:", id)});
  if (reply.elements.size() != 3 || reply.elements[0].nil()) return std::nullopt;
  try {
    SessionRecord r = decode_session_record(reply.elements[0].str);
    if (!reply.elements[1].nil()) apply_session_progress(reply.elements[1].str, r);
    if (!reply.elements[2].nil()) r.history = reply.elements[2].str;
    return r;
  } catch (const std::exception& e) {
    throw SessionUnusable("the stored record of session " + id + " is unreadable: " + e.what());
  }
}

bool RedisSessionStore::exists(const std::string& id) {
  return redis_->command({"EXISTS", key("session:", id)}).integer == 1;
}

void RedisSessionStore::remove(const std::string& id) {
  redis_->command({"DEL", key("session:", id), key("state:", id), key("history:", id), key("lease:", id), key("handoff:", id)});
}

std::vector<std::string> RedisSessionStore::list() {
  std::vector<std::string> ids;
  const std::string pattern = key("session:", "*");
  const std::size_t skip = options_.prefix.size() + 8;
  std::string cursor = "0";
  do {
    const RedisReply r = redis_->command({"SCAN", cursor, "MATCH", pattern, "COUNT", "1000"});
    if (r.elements.size() != 2) throw StoreUnavailable("Redis SCAN answered an unexpected reply");
    cursor = r.elements[0].str;
    for (const auto& k : r.elements[1].elements) ids.push_back(k.str.substr(skip));
  } while (cursor != "0");
  return ids;
}

Claim RedisSessionStore::claim(const std::string& id, bool take_over) {
  const std::string lease = key("lease:", id), handoff = key("handoff:", id);
  const RedisReply r = redis_->eval(kClaim, {lease, handoff}, {options_.replica_id, lease_ms_, take_over ? "1" : "0"});
  if (r.elements.size() != 3) throw StoreUnavailable("Redis answered an unexpected reply to a lease claim");
  Claim c;
  c.acquired = r.elements[0].integer == 1;
  if (!c.acquired) {
    c.owner_id = r.elements[1].str;
    c.owner_address = address_of(c.owner_id);
    c.lease_ms_left = std::max<long long>(0, r.elements[2].integer);
  }
  return c;
}

Renewal RedisSessionStore::renew(const std::string& id, bool may_hand_off) {
  const std::string lease = key("lease:", id), handoff = key("handoff:", id);
  const long long r = redis_->eval(kRenew, {lease, handoff}, {options_.replica_id, lease_ms_, may_hand_off ? "1" : "0"}).integer;
  return r == 1 ? Renewal::kHeld : r == 2 ? Renewal::kHandOff : Renewal::kLost;
}

void RedisSessionStore::release(const std::string& id) { redis_->eval(kRelease, {key("lease:", id)}, {options_.replica_id}); }

void RedisSessionStore::heartbeat() {
  std::string address;
  {
    std::lock_guard lock(advertise_mutex_);
    address = advertise_;
  }
  redis_->command({"SET", key("replica:", options_.replica_id), address, "PX", lease_ms_});
}

std::string RedisSessionStore::owner_of(const std::string& id) {
  const RedisReply r = redis_->command({"GET", key("lease:", id)});
  return r.nil() ? std::string() : r.str;
}

std::string RedisSessionStore::address_of(const std::string& replica) {
  const RedisReply r = redis_->command({"GET", key("replica:", replica)});
  return r.nil() ? std::string() : r.str;
}

}  // namespace filigree::server
