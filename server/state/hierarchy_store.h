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
};

}  // namespace filigree::server
