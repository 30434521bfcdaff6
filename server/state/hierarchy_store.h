#pragma once
// Hierarchy files (.fgh bytes) shared between replicas, by cache key (mesh
// hash and base-size request): one replica builds, every other one loads.

#include <optional>
#include <string>

namespace filigree::server {

class HierarchyStore {
 public:
  virtual ~HierarchyStore() = default;
  // The bytes stored under `key`, or nullopt. Throws StoreUnavailable.
  virtual std::optional<std::string> get(const std::string& key) = 0;
  // Stores `bytes` under `key` (the same key always means the same bytes;
  // a corrupt copy is replaced).
  virtual void put(const std::string& key, const std::string& bytes) = 0;

  // So that two replicas given the same new mesh at once preprocess it once:
  // try_claim_build is true if this process may build `key` now (it then
  // holds the claim for a while), renew_build extends the claim during a long
  // build, end_build drops it. A claim whose holder died expires.
  virtual bool try_claim_build(const std::string& key) = 0;
  virtual void renew_build(const std::string& key) = 0;
  virtual void end_build(const std::string& key) = 0;
};

}  // namespace filigree::server
