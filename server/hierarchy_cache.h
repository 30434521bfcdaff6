#pragma once
// Hierarchies by mesh hash and base size: the same mesh uploaded twice is
// preprocessed once (even concurrently), kept in memory while any session uses
// it and on disk under --data-dir/hierarchies/ for restarts.

#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "hierarchy/hierarchy.h"
#include "preprocess/preprocess.h"

namespace filigree::server {

class HierarchyCache {
 public:
  // `dir` empty: memory only.
  explicit HierarchyCache(std::filesystem::path dir);

  // The cache key: mesh hash and the base-size request.
  static std::string key_of(std::uint64_t mesh_hash, const PreprocessOptions& options);

  // Returns the hierarchy for `mesh` (already validated and repaired),
  // building it at most once per key; `built` tells whether this call built it.
  std::shared_ptr<const Hierarchy> get_or_build(const TriMesh& mesh, const PreprocessOptions& options,
                                                std::string* key, bool* built);
  // A hierarchy by key from memory or disk; throws if it is neither.
  std::shared_ptr<const Hierarchy> load(const std::string& key);

  std::size_t builds() const;

 private:
  std::filesystem::path file_of(const std::string& key) const;

  const std::filesystem::path dir_;
  mutable std::mutex mutex_;
  std::map<std::string, std::weak_ptr<const Hierarchy>> loaded_;
  std::map<std::string, std::shared_future<std::shared_ptr<const Hierarchy>>> building_;
  std::size_t builds_ = 0;
};

}  // namespace filigree::server
