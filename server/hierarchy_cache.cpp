#include "server/hierarchy_cache.h"

#include <cstdio>

#include <spdlog/spdlog.h>

#include "hierarchy/hierarchy_file.h"
#include "util/content_hash.h"

namespace filigree::server {

HierarchyCache::HierarchyCache(std::filesystem::path dir) : dir_(std::move(dir)) {
  if (!dir_.empty()) std::filesystem::create_directories(dir_);
}

std::string HierarchyCache::key_of(std::uint64_t mesh_hash, const PreprocessOptions& options) {
  char spec[64];
  if (options.base_vertices) {
    std::snprintf(spec, sizeof spec, "n%zu", *options.base_vertices);
  } else if (options.ratio) {
    std::snprintf(spec, sizeof spec, "r%.6g", *options.ratio);
  } else {
    std::snprintf(spec, sizeof spec, "default");
  }
  return hash_to_hex(mesh_hash) + "-" + spec;
}

std::filesystem::path HierarchyCache::file_of(const std::string& key) const { return dir_ / (key + ".fgh"); }

std::shared_ptr<const Hierarchy> HierarchyCache::get_or_build(const TriMesh& mesh, const PreprocessOptions& options,
                                                              std::string* key_out, bool* built) {
  const std::string key = key_of(hash_mesh(mesh), options);
  if (key_out) *key_out = key;
  if (built) *built = false;
  std::promise<std::shared_ptr<const Hierarchy>> promise;
  std::shared_future<std::shared_ptr<const Hierarchy>> wait_for;
  bool we_build = false;
  {
    std::lock_guard lock(mutex_);
    if (auto h = loaded_[key].lock()) return h;
    const auto it = building_.find(key);
    if (it != building_.end()) {
      wait_for = it->second;
    } else if (dir_.empty() || !std::filesystem::exists(file_of(key))) {
      building_[key] = promise.get_future().share();
      we_build = true;
    }
  }
  if (wait_for.valid()) return wait_for.get();  // someone else builds it: share the result (or its error)
  if (!we_build) return load(key);

  std::shared_ptr<const Hierarchy> h;
  try {
    h = std::make_shared<const Hierarchy>(preprocess(mesh, options));
    if (!dir_.empty()) save_hierarchy(*h, file_of(key));
  } catch (...) {
    std::lock_guard lock(mutex_);
    promise.set_exception(std::current_exception());
    building_.erase(key);
    throw;
  }
  spdlog::info("event=hierarchy_built key={} vertices={} base={} seconds={:.2f}", key, h->vertex_count(),
               h->base_vertices.size(), h->build.build_seconds);
  if (built) *built = true;
  std::lock_guard lock(mutex_);
  loaded_[key] = h;
  ++builds_;
  promise.set_value(h);
  building_.erase(key);
  return h;
}

std::shared_ptr<const Hierarchy> HierarchyCache::load(const std::string& key) {
  {
    std::lock_guard lock(mutex_);
    if (auto h = loaded_[key].lock()) return h;
  }
  if (dir_.empty()) throw std::runtime_error("hierarchy " + key + " is not in memory and there is no data directory");
  auto h = std::make_shared<const Hierarchy>(load_hierarchy(file_of(key)));
  std::lock_guard lock(mutex_);
  if (auto existing = loaded_[key].lock()) return existing;
  loaded_[key] = h;
  return h;
}

std::size_t HierarchyCache::builds() const {
  std::lock_guard lock(mutex_);
  return builds_;
}

}  // namespace filigree::server
