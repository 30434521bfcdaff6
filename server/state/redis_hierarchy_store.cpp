#include "server/state/redis_hierarchy_store.h"

#include "server/state/redis_client.h"

namespace filigree::server {

RedisHierarchyStore::RedisHierarchyStore(std::shared_ptr<RedisClient> redis, std::string prefix)
    : redis_(std::move(redis)), prefix_(std::move(prefix) + "hierarchy:") {}

std::optional<std::string> RedisHierarchyStore::get(const std::string& key) {
  RedisReply r = redis_->command({"GET", prefix_ + key});
  if (r.nil()) return std::nullopt;
  return std::move(r.str);
}

void RedisHierarchyStore::put(const std::string& key, const std::string& bytes) {
  // Overwrites: the same key means the same bytes, unless the stored copy is corrupt.
  redis_->command({"SET", prefix_ + key, bytes});
}

}  // namespace filigree::server
