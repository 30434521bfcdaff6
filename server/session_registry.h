#pragma once
// The server's sessions: creation with fresh ids and tokens, lookup, limits,
// persistence of each session's record under --data-dir/sessions/, restore at
// start, and eviction of idle sessions from memory (their records stay, and a
// later request loads them again).

#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "server/hierarchy_cache.h"
#include "server/session.h"

namespace filigree::server {

struct RegistryLimits {
  std::size_t max_sessions = 64;
  double idle_seconds = 3600.0;
};

// More sessions than --max-sessions.
struct TooManySessions : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class SessionRegistry {
 public:
  // `data_dir` empty: nothing is persisted.
  SessionRegistry(HierarchyCache& cache, std::filesystem::path data_dir, RegistryLimits limits);
  ~SessionRegistry();

  std::shared_ptr<Session> create(std::shared_ptr<const Hierarchy> h, const std::string& hierarchy_key,
                                  const v1::SessionOptions& options, std::vector<Index> uploaded_ids);
  // nullptr for an unknown (or closed) session; evicted sessions are reloaded.
  std::shared_ptr<Session> find(const std::string& id);
  // Closes the session's streams and deletes its record; false if unknown.
  bool close(const std::string& id);
  std::vector<std::shared_ptr<Session>> loaded() const;

  // Loads every persisted session (at start).
  std::size_t restore();
  // Writes the records of sessions whose version changed, evicts idle ones.
  void maintain();
  // Finishes every stream (UNAVAILABLE) and writes every record.
  void shutdown();

 private:
  std::shared_ptr<Session> load_record(const std::filesystem::path& file);
  void persist(const Session& s);
  std::filesystem::path record_file(const std::string& id) const;

  HierarchyCache& cache_;
  const std::filesystem::path dir_;
  const RegistryLimits limits_;
  mutable std::mutex mutex_;
  std::map<std::string, std::shared_ptr<Session>> sessions_;
  std::map<std::string, std::uint64_t> persisted_version_;
};

// 128 random bits as 32 hex digits.
std::string random_token();

}  // namespace filigree::server
