#pragma once
// Hierarchies by mesh hash and base size: the same mesh uploaded twice is
// preprocessed once (even concurrently), kept in memory while any session uses
// it, on disk under --data-dir/hierarchies/ for restarts and, with replicas,
// in the shared store so a hierarchy built by one replica is loaded by others.

#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "hierarchy/hierarchy.h"
#include "preprocess/preprocess.h"
#include "server/state/hierarchy_store.h"

namespace filigree::server {

class HierarchyCache {
 public:
  // `dir` empty: no local files. `shared` (may be null, must outlive the
  // cache): the store shared by replicas.
  explicit HierarchyCache(std::filesystem::path dir, HierarchyStore* shared = nullptr);

  // The cache key: mesh hash and the base-size request.
  static std::string key_of(std::uint64_t mesh_hash, const PreprocessOptions& options);

  // Returns the hierarchy for `mesh` (already validated and repaired),
  // building it at most once per key (with a shared store, across replicas:
  // a build another replica runs is waited for); `built` tells whether this
  // call built it.
  std::shared_ptr<const Hierarchy> get_or_build(const TriMesh& mesh, const PreprocessOptions& options,
                                                std::string* key, bool* built);
  // A hierarchy by key from memory, disk or the shared store; throws if it
  // is in none.
  std::shared_ptr<const Hierarchy> load(const std::string& key);

  // Deletes the files of hierarchies that are not in `in_use`, not loaded
  // and not being built, but the `keep_unused` most recently written.
  // Returns how many it deleted.
  std::size_t collect(const std::set<std::string>& in_use, std::size_t keep_unused);

  std::size_t builds() const;
  // Hierarchies this process loaded from the shared store (built elsewhere).
  std::size_t shared_loads() const;

 private:
  std::filesystem::path file_of(const std::string& key) const;
  // From the shared store (kept on local disk too), or nullptr.
  std::shared_ptr<const Hierarchy> fetch_shared(const std::string& key);
  // The shared copy, waiting while another replica builds it; nullptr when
  // this process should build it (and then holds the shared build claim).
  std::shared_ptr<const Hierarchy> shared_or_claim(const std::string& key, const std::function<void(double)>& progress);
  void end_claim(const std::string& key);
  std::shared_ptr<const Hierarchy> remember(const std::string& key, std::shared_ptr<const Hierarchy> h);

  const std::filesystem::path dir_;
  HierarchyStore* const shared_;
  mutable std::mutex mutex_;
  std::map<std::string, std::weak_ptr<const Hierarchy>> loaded_;
  std::map<std::string, std::shared_future<std::shared_ptr<const Hierarchy>>> building_;
  std::size_t builds_ = 0, shared_loads_ = 0;
};

}  // namespace filigree::server
