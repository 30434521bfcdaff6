#include "server/state/redis_hierarchy_store.h"

#include <random>

#include "server/state/redis_client.h"

namespace filigree::server {
namespace {

constexpr char kClaimMs[] = "30000";

// KEYS: claim. ARGV: holder, ms. Extends the claim if it is ours.
constexpr std::string_view kRenew = R"(
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('PEXPIRE', KEYS[1], ARGV[2]) end
return 0)";

// KEYS: claim. ARGV: holder. Drops the claim if it is ours.
constexpr std::string_view kEnd = R"(
if redis.call('GET', KEYS[1]) == ARGV[1] then return redis.call('DEL', KEYS[1]) end
return 0)";

std::string random_holder() {
  std::random_device device;
  return std::to_string(device()) + "-" + std::to_string(device());
}

}  // namespace

RedisHierarchyStore::RedisHierarchyStore(std::shared_ptr<RedisClient> redis, std::string prefix)
    : redis_(std::move(redis)), prefix_(prefix + "hierarchy:"), claim_prefix_(prefix + "building:"), holder_(random_holder()) {}

std::optional<std::string> RedisHierarchyStore::get(const std::string& key) {
  RedisReply r = redis_->command({"GET", prefix_ + key});
  if (r.nil()) return std::nullopt;
  return std::move(r.str);
}

void RedisHierarchyStore::put(const std::string& key, const std::string& bytes) {
  // Overwrites: the same key means the same bytes, unless the stored copy is corrupt.
  redis_->command({"SET", prefix_ + key, bytes});
}

bool RedisHierarchyStore::try_claim_build(const std::string& key) {
  return !redis_->command({"SET", claim_prefix_ + key, holder_, "NX", "PX", kClaimMs}).nil();
}

void RedisHierarchyStore::renew_build(const std::string& key) {
  redis_->eval(kRenew, {claim_prefix_ + key}, {holder_, kClaimMs});
}

void RedisHierarchyStore::end_build(const std::string& key) { redis_->eval(kEnd, {claim_prefix_ + key}, {holder_}); }

}  // namespace filigree::server
