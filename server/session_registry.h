#pragma once
// The server's sessions: creation with fresh ids and tokens, lookup, limits,
// records in a SessionStore (files under --data-dir, or Redis shared by
// replicas), restore at start, eviction of idle sessions from memory (their
// records stay, and a later request loads them again) and, with a shared
// store, the lease that makes exactly one replica compute each session.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "server/edit_history.h"
#include "server/hierarchy_cache.h"
#include "server/session.h"
#include "server/session_assets.h"
#include "server/state/session_store.h"

namespace filigree::server {

struct RegistryLimits {
  std::size_t max_sessions = 64;
  double idle_seconds = 3600.0;
  // A replica keeps a session at least this long before handing it to
  // another that asks for it (no ping-pong between two routes).
  double min_hold_seconds = 2.0;
  // The lease's length (shared store): a replica that could not renew a
  // lease for this long stops computing the session.
  double lease_seconds = 3.0;
  // Threads computing and encoding every session's frames; 0: one per core.
  unsigned frame_threads = 0;
  // Each session's edit history keeps at most this much.
  HistoryLimits history;
};

// More sessions than --max-sessions.
struct TooManySessions : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A proposed session id that is malformed or taken.
struct BadSessionId : std::invalid_argument {
  BadSessionId(const std::string& message, bool taken) : std::invalid_argument(message), taken(taken) {}
  bool taken;
};

struct SessionLocation {
  bool exists = false;
  std::string replica_id, address;  // empty: no replica serves it now
  bool here = false;
};

class SessionRegistry {
 public:
  // `store` must outlive the registry.
  SessionRegistry(HierarchyCache& cache, SessionStore& store, RegistryLimits limits);
  ~SessionRegistry();

  // A new session under `proposed_id` (20 lowercase hex digits, so that a
  // load balancer routing by x-session-id sends the upload where the session
  // will live), or under a fresh id when it is empty. Throws BadSessionId
  // (taken) if a session of that id exists anywhere this server knows of —
  // loaded, evicted, being created, or in the store — and TooManySessions
  // at --max-sessions (evicted sessions and creations in progress count).
  std::shared_ptr<Session> create(std::shared_ptr<const Hierarchy> h, const std::string& hierarchy_key,
                                  const v1::SessionOptions& options, std::vector<Index> uploaded_ids,
                                  const std::string& proposed_id = {}, std::string rig = {}, std::string owner = {});
  // nullptr for an unknown (or closed) session; evicted sessions and, with a
  // shared store, sessions of other replicas whose lease is free are loaded.
  // Throws SessionElsewhere while another replica holds the lease (asking it
  // to hand the session over if `take_over`), StoreUnavailable if the shared
  // store cannot be reached.
  std::shared_ptr<Session> find(const std::string& id, bool take_over = true);
  // Whether find(id) would answer from memory, without loading: the
  // session is loaded here and computing. (It may be evicted right after.)
  bool in_memory(const std::string& id) const;
  // Which replica serves the session, without loading it.
  SessionLocation locate(const std::string& id);
  // Whether `token` (a session token) or `owner` (an API key's name; empty:
  // none) reaches session `id`, without loading it. False for an unknown id.
  // Throws StoreUnavailable if the shared store cannot be reached.
  bool reachable(const std::string& id, const std::string& token, const std::string& owner);
  // Whether a session of this id exists anywhere this server knows of.
  bool taken(const std::string& id);
  // Closes the session's streams and deletes its record; false if unknown.
  bool close(const std::string& id);
  std::vector<std::shared_ptr<Session>> loaded() const;
  // What the sessions of API key `owner` hold: loaded ones and those evicted
  // from memory (their records stay). With a shared store, the sessions this
  // replica has served since it started.
  struct Holdings {
    std::uint64_t sessions = 0, vertices = 0;
  };
  Holdings holdings(const std::string& owner) const;

  // Deletes the hierarchy files no session known here uses, but the
  // `keep_unused` newest (a mesh uploaded again soon is not preprocessed
  // again); returns how many went. Called at start, and by maintain() after
  // a session closed.
  std::size_t collect_hierarchies(std::size_t keep_unused = kUnusedHierarchiesKept);
  static constexpr std::size_t kUnusedHierarchiesKept = 4;

  // Loads every persisted session (at start; a shared store loads lazily).
  std::size_t restore();
  // Every tick: writes changed records (local store) or renews leases
  // (shared store: sessions whose lease was lost or asked for leave this
  // replica), and evicts idle sessions.
  void maintain();
  // Evicts sessions no stream uses (their records stay; a later request
  // loads them again), the longest idle first, until `enough()` says so or
  // none is left. Returns how many were evicted. For --max-memory.
  std::size_t evict_idle_until(const std::function<bool()>& enough);
  // Finishes every stream (UNAVAILABLE), writes every record and releases
  // every lease, so another replica can take the sessions at once.
  void shutdown();

  SessionStore& store() { return store_; }
  // Meshes whose shared session assets (model, base and rest meshes) are alive.
  std::size_t live_meshes() const { return assets_.live(); }

 private:
  struct Entry {
    std::shared_ptr<Session> session;
    std::uint64_t persisted_version = 0;
    std::chrono::steady_clock::time_point since, renewed;
  };
  std::shared_ptr<Session> load(const std::string& id, bool take_over);
  std::shared_ptr<Session> insert(std::shared_ptr<Session> s);
  // Throws SessionElsewhere if the lease passed to another replica meanwhile; extends it otherwise.
  void confirm_lease(const std::string& id);
  // Writes the record of a session that evict_if_unused() closed and
  // removes it from this process (`why`: for the log).
  void evict(const std::string& id, const Session& s, const char* why);
  // Removes the session from this process (not from the store), ending its streams with `why`.
  void drop(const std::string& id, const std::string& why);
  void persist(const Session& s);
  Journal journal_for(const std::string& id);

  HierarchyCache& cache_;
  SessionAssetsCache assets_;
  SessionStore& store_;
  const RegistryLimits limits_;
  // Declared before sessions_: sessions end (and drain their lanes) before it stops.
  FrameScheduler scheduler_;
  mutable std::mutex mutex_;
  std::map<std::string, Entry> sessions_;
  // Owner and vertex count of every owned session known here, loaded or
  // evicted (for API-key quotas); entries go when the session is closed or
  // moves to another replica.
  std::map<std::string, std::pair<std::string, std::uint64_t>> owned_;
  std::map<std::string, std::shared_ptr<std::mutex>> loading_;
  // Sessions evicted from memory whose records this machine keeps (local
  // store), and ids reserved by a create in progress: both count against
  // --max-sessions, and neither id can be proposed for a new session.
  std::map<std::string, std::string> evicted_;  // id → hierarchy key
  std::set<std::string> creating_;
  std::atomic<bool> collect_pending_{false};  // a session closed since the last collect_hierarchies()
  std::size_t counted_locked() const;
};

}  // namespace filigree::server
