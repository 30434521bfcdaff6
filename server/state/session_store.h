#pragma once
// Where session records live and which replica computes each session
// (DESIGN §4). Two implementations: FileSessionStore (one machine, records
// under --data-dir, this process owns everything) and RedisSessionStore
// (replicas share records and hold a lease per session).

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "server/session_record.h"

namespace filigree::server {

// The shared store cannot be reached or answered an error: the request can
// be retried (→ UNAVAILABLE).
struct StoreUnavailable : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A stored record or hierarchy is unreadable (→ DATA_LOSS): retrying will
// not help; the message says what is wrong.
struct SessionUnusable : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// This replica does not (or no longer) own the session: another replica's
// lease holds it (→ UNAVAILABLE, naming the owner).
struct SessionElsewhere : std::runtime_error {
  SessionElsewhere(const std::string& session, std::string owner_id, std::string owner_address,
                   std::int64_t retry_after_ms, bool moving_here);
  std::string owner_id, owner_address;  // address empty: the owner is not registered (likely dead)
  std::int64_t retry_after_ms;
};

// The outcome of claiming a session.
struct Claim {
  bool acquired = false;
  std::string owner_id;          // when not acquired
  std::string owner_address;     // the owner's advertised address, if it is alive
  std::int64_t lease_ms_left = 0;
};

enum class Renewal { kHeld, kLost, kHandOff };

class SessionStore {
 public:
  virtual ~SessionStore() = default;

  // Shared between replicas: every accepted change is journaled before it is
  // acknowledged, and sessions are owned through leases.
  virtual bool shared() const = 0;
  // Keeps sessions across restarts (false: memory only, nothing to journal).
  virtual bool persistent() const { return true; }
  // This replica's id and advertised address (empty for a local store).
  virtual std::string replica_id() const { return {}; }

  // Stores a new session and claims it; false if the id is taken.
  virtual bool create(const SessionRecord& r) = 0;
  // Overwrites the record if this replica still owns the session; false if not.
  virtual bool save(const SessionRecord& r) = 0;
  // Overwrites only what changes while the session runs (the journal of a
  // shared store); false if this replica no longer owns the session.
  virtual bool save_progress(const std::string& id, const SessionProgress& p) = 0;
  // Overwrites the session's edit history (EditHistory::serialize), which
  // load() returns in SessionRecord::history; false if the session is gone
  // (or, shared, owned by another replica now). A store that keeps nothing
  // keeps no history either.
  virtual bool save_history(const std::string& id, const std::string& bytes) {
    (void)id, (void)bytes;
    return true;
  }
  // nullopt if there is none; throws SessionUnusable if it is unreadable.
  virtual std::optional<SessionRecord> load(const std::string& id) = 0;
  virtual bool exists(const std::string& id) = 0;
  // Deletes the record (and lease).
  virtual void remove(const std::string& id) = 0;
  // Every stored session id (a local store restores them all at start).
  virtual std::vector<std::string> list() = 0;

  // Takes the session's lease if it is free or ours. If another replica
  // holds it and `take_over`, asks that replica to hand it over.
  virtual Claim claim(const std::string& id, bool take_over) = 0;
  // Extends the lease; kHandOff: another replica asked for the session and
  // `may_hand_off`, so the caller should release it.
  virtual Renewal renew(const std::string& id, bool may_hand_off) = 0;
  virtual void release(const std::string& id) = 0;
  // Called every maintenance tick: keeps this replica's address registered.
  virtual void heartbeat() {}
  // The replica holding the session's lease (empty: none, or a local store).
  virtual std::string owner_of(const std::string& id) { (void)id; return {}; }
  // Where replica `id` says it can be reached (empty if it is not registered).
  virtual std::string address_of(const std::string& replica) { (void)replica; return {}; }
};

}  // namespace filigree::server
