#pragma once
// Hierarchy files in Redis under <prefix>hierarchy:<key>; build claims under
// <prefix>building:<key> (30 s, renewed while the build reports progress). Redis strings hold
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
  bool try_claim_build(const std::string& key) override;
  void renew_build(const std::string& key) override;
  void end_build(const std::string& key) override;

 private:
  std::shared_ptr<RedisClient> redis_;
  const std::string prefix_, claim_prefix_;
  const std::string holder_;  // this process, in build claims
};

}  // namespace filigree::server
