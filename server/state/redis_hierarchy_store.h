#pragma once
// Hierarchy files in Redis under <prefix>hierarchy:<key>. Redis strings hold
// at most 512 MiB: about 2 million vertices of hierarchy.

#include <memory>

#include "server/state/hierarchy_store.h"

namespace filigree::server {

class RedisClient;

class RedisHierarchyStore final : public HierarchyStore {
 public:
  RedisHierarchyStore(std::shared_ptr<RedisClient> redis, std::string prefix);
  std::optional<std::string> get(const std::string& key) override;
  void put(const std::string& key, const std::string& bytes) override;

 private:
  std::shared_ptr<RedisClient> redis_;
  const std::string prefix_;
};

}  // namespace filigree::server
