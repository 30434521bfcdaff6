#include "server/hierarchy_cache.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <thread>

#include <spdlog/spdlog.h>

#include "hierarchy/hierarchy_file.h"
#include "util/content_hash.h"

namespace filigree::server {
namespace {

// Write then rename: a crash leaves no half file under the final name.
void write_file(const std::filesystem::path& file, const std::string& bytes) {
  // Unique per writer: two threads may fetch the same hierarchy at once.
  std::ostringstream name;
  name << file.string() << "." << std::this_thread::get_id() << ".partial";
  const auto tmp = std::filesystem::path(name.str());
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())))
      throw std::runtime_error("cannot write " + tmp.string());
  }
  std::filesystem::rename(tmp, file);
}

}  // namespace

HierarchyCache::HierarchyCache(std::filesystem::path dir, HierarchyStore* shared) : dir_(std::move(dir)), shared_(shared) {
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
  // The format version is part of the key: a server never reads a cached
  // hierarchy of another format; it builds (and shares) its own.
  return hash_to_hex(mesh_hash) + "-" + spec + "-v" + std::to_string(kHierarchyFormatVersion);
}

std::filesystem::path HierarchyCache::file_of(const std::string& key) const { return dir_ / (key + ".fgh"); }

std::size_t HierarchyCache::collect(const std::set<std::string>& in_use, std::size_t keep_unused) {
  if (dir_.empty() || !std::filesystem::exists(dir_)) return 0;
  std::vector<std::pair<std::filesystem::file_time_type, std::filesystem::path>> unused;
  // Under the lock: a hierarchy cannot start loading or building meanwhile.
  std::lock_guard lock(mutex_);
  for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
    if (entry.path().extension() != ".fgh") continue;
    const std::string key = entry.path().stem().string();
    if (in_use.count(key) || building_.count(key)) continue;
    if (const auto it = loaded_.find(key); it != loaded_.end() && !it->second.expired()) continue;
    std::error_code error;
    const auto written = entry.last_write_time(error);
    if (!error) unused.emplace_back(written, entry.path());
  }
  if (unused.size() <= keep_unused) return 0;
  std::sort(unused.begin(), unused.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::size_t removed = 0;
  for (std::size_t i = keep_unused; i < unused.size(); ++i) {
    std::error_code error;
    removed += std::filesystem::remove(unused[i].second, error) ? 1 : 0;
  }
  return removed;
}

std::shared_ptr<const Hierarchy> HierarchyCache::remember(const std::string& key, std::shared_ptr<const Hierarchy> h) {
  std::lock_guard lock(mutex_);
  if (auto existing = loaded_[key].lock()) return existing;
  loaded_[key] = h;
  return h;
}

std::shared_ptr<const Hierarchy> HierarchyCache::fetch_shared(const std::string& key) {
  if (!shared_) return nullptr;
  std::optional<std::string> bytes = shared_->get(key);
  if (!bytes) return nullptr;
  auto h = std::make_shared<const Hierarchy>(deserialize_hierarchy(*bytes, "shared hierarchy " + key));
  if (!dir_.empty()) write_file(file_of(key), *bytes);
  spdlog::info("event=hierarchy_fetched key={} bytes={}", key, bytes->size());
  std::lock_guard lock(mutex_);
  ++shared_loads_;
  return h;
}

void HierarchyCache::end_claim(const std::string& key) {
  try {
    shared_->end_build(key);
  } catch (const std::exception& e) {  // it expires
    spdlog::warn("event=build_claim_release_failed key={} error=\"{}\"", key, e.what());
  }
}

std::shared_ptr<const Hierarchy> HierarchyCache::shared_or_claim(const std::string& key,
                                                                 const std::function<void(double)>& progress) {
  if (!shared_) return nullptr;
  const auto fetch = [&]() -> std::shared_ptr<const Hierarchy> {
    try {
      return fetch_shared(key);
    } catch (const HierarchyFileError& e) {
      // We have the mesh: build it again, and replace the corrupt copy.
      spdlog::warn("event=shared_hierarchy_corrupt key={} error=\"{}\"", key, e.what());
      return nullptr;
    }
  };
  while (true) {
    if (auto h = fetch()) return h;
    if (shared_->try_claim_build(key)) {
      // Its builder may have finished between our look and our claim.
      if (auto h = fetch()) {
        end_claim(key);
        return h;
      }
      return nullptr;
    }
    // Another replica is building it: wait for its result (its claim expires if it dies).
    if (progress) progress(0.0);
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
}

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
  if (wait_for.valid()) {
    // Someone else builds it: share the result (or its error), unless this
    // call is stopped first (its upload cancelled: checked every 20 ms).
    while (wait_for.wait_for(std::chrono::milliseconds(20)) != std::future_status::ready)
      if (options.stop && options.stop->load()) throw PreprocessingStopped();
    try {
      return wait_for.get();
    } catch (const PreprocessingStopped&) {
      // The build stopped because its own upload gave up: not this call's
      // error. Build it here (unless this call is stopped too).
      if (options.stop && options.stop->load()) throw;
      return get_or_build(mesh, options, key_out, built);
    }
  }
  if (!we_build) {
    try {
      return load(key);
    } catch (const HierarchyFileError& e) {
      // A damaged cache file: the mesh is at hand, so build it again.
      spdlog::warn("event=cached_hierarchy_unreadable key={} error=\"{}\"", key, e.what());
      std::error_code ignored;
      std::filesystem::remove(file_of(key), ignored);
      return get_or_build(mesh, options, key_out, built);
    }
  }

  std::shared_ptr<const Hierarchy> h;
  bool fetched = false, claimed = false;
  try {
    // Another replica may have built it already, or be building it now.
    h = shared_or_claim(key, options.progress);
    fetched = h != nullptr;
    claimed = shared_ && !fetched;
    if (!h) {
      PreprocessOptions o = options;
      if (claimed) {
        // Keep the build claim while the build reports progress (at most once a second).
        o.progress = [this, &key, &options, last = std::chrono::steady_clock::now()](double f) mutable {
          if (options.progress) options.progress(f);
          if (std::chrono::steady_clock::now() - last < std::chrono::seconds(1)) return;
          last = std::chrono::steady_clock::now();
          try {
            shared_->renew_build(key);
          } catch (const std::exception& e) {  // the claim then expires: at worst another replica builds too
            spdlog::warn("event=build_claim_renewal_failed key={} error=\"{}\"", key, e.what());
          }
        };
      }
      h = std::make_shared<const Hierarchy>(preprocess(mesh, o));
      if (!dir_.empty() || shared_) {
        const std::string bytes = serialize_hierarchy(*h);
        if (!dir_.empty()) write_file(file_of(key), bytes);
        if (shared_) shared_->put(key, bytes);
      }
      if (claimed) end_claim(key);
    }
  } catch (...) {
    if (claimed) end_claim(key);
    std::lock_guard lock(mutex_);
    promise.set_exception(std::current_exception());
    building_.erase(key);
    throw;
  }
  if (!fetched) {
    spdlog::info("event=hierarchy_built key={} vertices={} base={} seconds={:.2f}", key, h->vertex_count(),
                 h->base_vertices.size(), h->build.build_seconds);
  }
  if (built) *built = !fetched;
  std::lock_guard lock(mutex_);
  loaded_[key] = h;
  if (!fetched) ++builds_;
  promise.set_value(h);
  building_.erase(key);
  return h;
}

std::shared_ptr<const Hierarchy> HierarchyCache::load(const std::string& key) {
  {
    std::lock_guard lock(mutex_);
    if (auto h = loaded_[key].lock()) return h;
  }
  if (!dir_.empty() && std::filesystem::exists(file_of(key)))
    return remember(key, std::make_shared<const Hierarchy>(load_hierarchy(file_of(key))));
  if (auto h = fetch_shared(key)) return remember(key, std::move(h));
  throw std::runtime_error("hierarchy " + key + " is in neither memory, the data directory nor the shared store");
}

std::size_t HierarchyCache::builds() const {
  std::lock_guard lock(mutex_);
  return builds_;
}

std::size_t HierarchyCache::shared_loads() const {
  std::lock_guard lock(mutex_);
  return shared_loads_;
}

}  // namespace filigree::server
