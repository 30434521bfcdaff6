#pragma once
// Session records and ownership leases in Redis, shared by every replica
// (DESIGN §4). Keys, under a prefix ("filigree:"):
//   session:<id>   the record (filigree.internal.SessionRecord bytes), written once
//   state:<id>     its options, pose and version, journaled on every change
//   lease:<id>     the id of the replica that computes the session, with a TTL
//   handoff:<id>   a replica that was sent the session's calls and asks for it
//   replica:<id>   a replica's advertised address, with a TTL (its heartbeat)
// Writes of a record are fenced by the lease (a Lua script): a replica that
// lost its lease can no longer overwrite what the new owner wrote.

#include <chrono>
#include <memory>
#include <mutex>

#include "server/state/session_store.h"

namespace filigree::server {

class RedisClient;

struct RedisSessionStoreOptions {
  std::string prefix = "filigree:";
  std::string replica_id;  // unique per replica
  std::string advertise;   // HOST:PORT at which clients reach this replica directly
  std::chrono::milliseconds lease{3000};
};

class RedisSessionStore final : public SessionStore {
 public:
  RedisSessionStore(std::shared_ptr<RedisClient> redis, RedisSessionStoreOptions options);

  bool shared() const override { return true; }
  std::string replica_id() const override { return options_.replica_id; }
  bool create(const SessionRecord& r) override;
  bool save(const SessionRecord& r) override;
  bool save_progress(const std::string& id, const SessionProgress& p) override;
  bool save_history(const std::string& id, const std::string& bytes) override;
  std::optional<SessionRecord> load(const std::string& id) override;
  bool exists(const std::string& id) override;
  void remove(const std::string& id) override;
  std::vector<std::string> list() override;
  Claim claim(const std::string& id, bool take_over) override;
  Renewal renew(const std::string& id, bool may_hand_off) override;
  void release(const std::string& id) override;
  void heartbeat() override;
  std::string address_of(const std::string& replica) override;
  std::string owner_of(const std::string& id) override;
  // Sets the advertised address (known once the server listens) and registers it.
  void set_advertise(std::string address);

 private:
  std::string key(const char* kind, const std::string& id) const { return options_.prefix + kind + id; }

  std::shared_ptr<RedisClient> redis_;
  const RedisSessionStoreOptions options_;
  mutable std::mutex advertise_mutex_;
  std::string advertise_;
  const std::string lease_ms_;
};

}  // namespace filigree::server
