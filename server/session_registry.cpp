#include "server/session_registry.h"

#include <algorithm>

#include <spdlog/spdlog.h>

#include "server/secret.h"

namespace filigree::server {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

}  // namespace

SessionRegistry::SessionRegistry(HierarchyCache& cache, SessionStore& store, RegistryLimits limits)
    : cache_(cache), store_(store), limits_(limits), scheduler_(limits.frame_threads) {}

SessionRegistry::~SessionRegistry() = default;

Journal SessionRegistry::journal_for(const std::string& id) {
  if (!store_.persistent()) return {};
  Journal j;
  if (!store_.shared()) {
    j.write = [this, id](const SessionProgress& p) {
      if (!store_.save_progress(id, p)) throw StoreUnavailable("session " + id + " was closed");
      std::lock_guard lock(mutex_);
      if (const auto it = sessions_.find(id); it != sessions_.end())
        it->second.persisted_version = std::max(it->second.persisted_version, p.version);
    };
    j.every_merge = false;
  } else {
    j.write = [this, id](const SessionProgress& p) {
      if (!store_.save_progress(id, p))
        throw StoreUnavailable("replica " + store_.replica_id() + " no longer holds the lease of session " + id +
                               "; another replica serves it: reconnect");
    };
    j.every_merge = true;
  }
  j.write_history = [this, id](const std::string& bytes) {
    if (!store_.save_history(id, bytes)) throw StoreUnavailable("session " + id + " was closed");
  };
  return j;
}

void SessionRegistry::confirm_lease(const std::string& id) {
  // Building a large session's first frame can outlast a lease: make sure
  // it is still ours (and extended) before serving it.
  const Claim claim = store_.claim(id, /*take_over=*/false);
  if (!claim.acquired) throw SessionElsewhere(id, claim.owner_id, claim.owner_address, claim.lease_ms_left, false);
}

std::shared_ptr<Session> SessionRegistry::insert(std::shared_ptr<Session> s) {
  std::lock_guard lock(mutex_);
  const auto now = Clock::now();
  const auto [it, inserted] = sessions_.emplace(s->id(), Entry{s, s->version(), now, now});
  if (inserted) evicted_.erase(s->id());
  if (!s->owner().empty()) owned_[s->id()] = {s->owner(), s->vertex_count()};
  return it->second.session;
}

std::size_t SessionRegistry::counted_locked() const { return sessions_.size() + evicted_.size() + creating_.size(); }

std::shared_ptr<Session> SessionRegistry::create(std::shared_ptr<const Hierarchy> h, const std::string& hierarchy_key,
                                                 const v1::SessionOptions& options, std::vector<Index> uploaded_ids,
                                                 const std::string& proposed_id, std::string rig, std::string owner) {
  if (!proposed_id.empty() && !is_session_id(proposed_id))
    throw BadSessionId("a proposed session id is " + std::to_string(kSessionIdLength) + " lowercase hex digits", false);
  SessionRecord r;
  r.id = proposed_id.empty() ? random_token().substr(0, kSessionIdLength) : proposed_id;
  {
    // The id is reserved before anything is stored: a session of that id
    // here (loaded, evicted, or being created) is never answered for, so a
    // proposed id can name a new session only (a memory-only store keeps no
    // record that would refuse it).
    std::lock_guard lock(mutex_);
    if (counted_locked() >= limits_.max_sessions)
      throw TooManySessions("the server holds its maximum of " + std::to_string(limits_.max_sessions) +
                            " sessions (--max-sessions; idle ones kept on disk count)");
    if (sessions_.count(r.id) || evicted_.count(r.id) || !creating_.insert(r.id).second)
      throw BadSessionId("the proposed session id is taken", true);
  }
  struct Unreserve {
    SessionRegistry& registry;
    const std::string id;
    ~Unreserve() {
      std::lock_guard lock(registry.mutex_);
      registry.creating_.erase(id);
    }
  } unreserve{*this, r.id};
  r.hierarchy_key = hierarchy_key;
  r.options = options;
  r.editor_token = random_token();
  r.viewer_token = random_token();
  r.uploaded_ids = std::move(uploaded_ids);
  r.rig = std::move(rig);
  r.owner = std::move(owner);
  if (!store_.create(r)) throw BadSessionId("the proposed session id is taken", true);
  Journal journal = journal_for(r.id);
  auto made = std::make_shared<Session>(std::move(r), assets_.get(h, scheduler_.threads()), scheduler_, std::move(journal), limits_.history);
  confirm_lease(made->id());
  auto s = insert(made);
  // Reserved above: nobody else can have inserted this id meanwhile.
  if (s != made) throw std::logic_error("session id " + made->id() + " was inserted twice");
  spdlog::info("event=session_created session={} key={}", s->id(), hierarchy_key);
  return s;
}

std::shared_ptr<Session> SessionRegistry::find(const std::string& id, bool take_over) {
  std::shared_ptr<Session> failed;
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(id);
    if (it != sessions_.end()) {
      if (it->second.session->failure().empty()) return it->second.session;
      // Its journal failed and it stopped computing: load it again from the store.
      failed = it->second.session;
      sessions_.erase(it);
    }
  }
  if (failed) failed->close_streams("the session is reloaded: reconnect");
  // Evicted, never loaded here, or another replica's.
  if (!is_session_id(id)) return nullptr;
  return load(id, take_over);
}

bool SessionRegistry::in_memory(const std::string& id) const {
  std::lock_guard lock(mutex_);
  const auto it = sessions_.find(id);
  return it != sessions_.end() && it->second.session->failure().empty();
}

std::shared_ptr<Session> SessionRegistry::load(const std::string& id, bool take_over) {
  // One load per session at a time: concurrent calls for it wait and share it.
  std::shared_ptr<std::mutex> loading;
  {
    std::lock_guard lock(mutex_);
    auto& m = loading_[id];
    if (!m) m = std::make_shared<std::mutex>();
    loading = m;
  }
  std::lock_guard load_lock(*loading);
  struct Forget {
    SessionRegistry& r;
    const std::string& id;
    ~Forget() {
      std::lock_guard lock(r.mutex_);
      r.loading_.erase(id);
    }
  } forget{*this, id};
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(id);
    if (it != sessions_.end()) return it->second.session;
  }
  if (!store_.exists(id)) return nullptr;
  const Claim claim = store_.claim(id, take_over);
  if (!claim.acquired) throw SessionElsewhere(id, claim.owner_id, claim.owner_address, claim.lease_ms_left, take_over);
  // Read after claiming: the previous owner wrote its last change before its lease ended.
  std::shared_ptr<Session> s;
  try {
    std::optional<SessionRecord> r = store_.load(id);
    if (!r) {
      store_.release(id);
      return nullptr;
    }
    auto h = cache_.load(r->hierarchy_key);
    s = std::make_shared<Session>(std::move(*r), assets_.get(h, scheduler_.threads()), scheduler_, journal_for(id), limits_.history);
  } catch (const StoreUnavailable&) {
    store_.release(id);
    throw;
  } catch (const std::exception& e) {
    // A corrupt record or hierarchy: say so; the lease goes back (nobody can compute it).
    store_.release(id);
    spdlog::error("event=session_unusable session={} error=\"{}\"", id, e.what());
    throw SessionUnusable(std::string(e.what()).find(id) != std::string::npos
                              ? std::string(e.what())
                              : "session " + id + " cannot be loaded: " + e.what());
  }
  confirm_lease(id);
  s = insert(std::move(s));
  spdlog::info("event=session_loaded session={} version={}", s->id(), s->version());
  return s;
}

void SessionRegistry::drop(const std::string& id, const std::string& why) {
  std::shared_ptr<Session> s;
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(id);
    if (it == sessions_.end()) return;
    s = it->second.session;
    sessions_.erase(it);
    owned_.erase(id);  // another replica serves it (or the next request loads it again)
  }
  s->close_streams(why);
}

SessionLocation SessionRegistry::locate(const std::string& id) {
  SessionLocation where;
  {
    std::lock_guard lock(mutex_);
    where.here = sessions_.count(id) > 0;
  }
  if (!where.here && (!is_session_id(id) || !store_.exists(id))) return where;
  where.exists = true;
  where.replica_id = where.here ? store_.replica_id() : store_.owner_of(id);
  if (!where.replica_id.empty()) where.address = store_.address_of(where.replica_id);
  where.here = where.here || (!store_.shared());
  return where;
}

bool SessionRegistry::reachable(const std::string& id, const std::string& token, const std::string& owner) {
  auto grants = [&](const std::string& editor, const std::string& viewer, const std::string& owned_by) {
    // Both tokens compared, in constant time, whatever the owner says.
    const bool by_token = !token.empty() && (same_secret(token, editor) | same_secret(token, viewer));
    return by_token || (!owner.empty() && owner == owned_by);
  };
  std::shared_ptr<Session> s;
  {
    std::lock_guard lock(mutex_);
    if (const auto it = sessions_.find(id); it != sessions_.end()) s = it->second.session;
  }
  if (s) return s->authorize(token) != Role::kNone || (!owner.empty() && owner == s->owner());
  if (!is_session_id(id) || !store_.exists(id)) return false;
  try {
    const std::optional<SessionRecord> r = store_.load(id);
    return r && grants(r->editor_token, r->viewer_token, r->owner);
  } catch (const SessionUnusable&) {
    return false;  // nobody can use it; its owner learns why when joining
  }
}

bool SessionRegistry::taken(const std::string& id) {
  {
    std::lock_guard lock(mutex_);
    if (sessions_.count(id) || evicted_.count(id) || creating_.count(id)) return true;
  }
  return store_.exists(id);
}

bool SessionRegistry::close(const std::string& id) {
  std::shared_ptr<Session> s = find(id);
  if (!s) return false;
  {
    std::lock_guard lock(mutex_);
    sessions_.erase(id);
    evicted_.erase(id);
    owned_.erase(id);
  }
  s->close();
  store_.remove(id);
  spdlog::info("event=session_closed session={}", id);
  // A closed session's hierarchy may be nobody's now: the next tick looks,
  // once the session (and its hold on the hierarchy) is gone.
  collect_pending_ = !store_.shared();
  return true;
}

std::size_t SessionRegistry::collect_hierarchies(std::size_t keep_unused) {
  std::set<std::string> in_use;
  {
    std::lock_guard lock(mutex_);
    for (const auto& [id, e] : sessions_) in_use.insert(e.session->hierarchy_key());
    for (const auto& [id, key] : evicted_) in_use.insert(key);
  }
  try {
    const std::size_t removed = cache_.collect(in_use, keep_unused);
    if (removed) spdlog::info("event=hierarchies_collected removed={}", removed);
    return removed;
  } catch (const std::exception& e) {  // a folder that cannot be listed: nothing is lost by keeping files
    spdlog::warn("event=hierarchy_collection_failed error=\"{}\"", e.what());
    return 0;
  }
}

SessionRegistry::Holdings SessionRegistry::holdings(const std::string& owner) const {
  std::lock_guard lock(mutex_);
  Holdings h;
  for (const auto& [id, entry] : owned_)
    if (entry.first == owner) {
      ++h.sessions;
      h.vertices += entry.second;
    }
  return h;
}

std::vector<std::shared_ptr<Session>> SessionRegistry::loaded() const {
  std::lock_guard lock(mutex_);
  std::vector<std::shared_ptr<Session>> out;
  for (const auto& [id, e] : sessions_) out.push_back(e.session);
  return out;
}

void SessionRegistry::persist(const Session& s) {
  try {
    // Only what changed since the session was created: the rest of its
    // record (the upload's ids, its rig, its tokens) is stored once.
    const SessionProgress p = s.progress();
    if (!store_.save_progress(s.id(), p)) return;
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(s.id());
    if (it != sessions_.end()) it->second.persisted_version = p.version;
  } catch (const std::exception& e) {
    spdlog::error("event=persist_failed session={} error=\"{}\"", s.id(), e.what());
  }
}

std::size_t SessionRegistry::restore() {
  if (store_.shared()) return 0;  // other replicas' sessions load when asked for
  std::size_t n = 0;
  for (const std::string& id : store_.list()) {
    try {
      if (find(id)) ++n;
    } catch (const std::exception& e) {
      spdlog::error("event=restore_failed session={} error=\"{}\"", id, e.what());
    }
  }
  return n;
}

void SessionRegistry::maintain() {
  const bool shared = store_.shared();
  if (shared) {
    try {
      store_.heartbeat();
    } catch (const std::exception& e) {
      spdlog::warn("event=heartbeat_failed error=\"{}\"", e.what());
    }
  }
  std::vector<std::pair<std::string, Entry>> entries;
  {
    std::lock_guard lock(mutex_);
    entries.assign(sessions_.begin(), sessions_.end());
  }
  for (const auto& [id, e] : entries) {
    const auto& s = e.session;
    s->persist_history(/*tick=*/true);  // the entries of gestures since the last tick
    s->flush_presence();
    if (shared) {
      Renewal renewal = Renewal::kHeld;
      try {
        renewal = store_.renew(id, seconds_since(e.since) >= limits_.min_hold_seconds);
        std::lock_guard lock(mutex_);
        const auto it = sessions_.find(id);
        if (it != sessions_.end()) it->second.renewed = Clock::now();
      } catch (const std::exception& ex) {
        spdlog::warn("event=lease_renewal_failed session={} error=\"{}\"", id, ex.what());
        // Past the lease another replica may own it: stop computing here.
        if (seconds_since(e.renewed) > limits_.lease_seconds) renewal = Renewal::kLost;
      }
      if (renewal == Renewal::kLost) {
        spdlog::warn("event=lease_lost session={}", id);
        drop(id, "this replica lost the session's lease; another replica serves it: reconnect");
        continue;
      }
      if (renewal == Renewal::kHandOff) {
        // Every change is journaled already; this write only makes sure.
        persist(*s);
        drop(id, "the session moved to another replica: reconnect");
        try {
          store_.release(id);
        } catch (const std::exception& ex) {
          spdlog::warn("event=lease_release_failed session={} error=\"{}\"", id, ex.what());
        }
        spdlog::info("event=session_handed_off session={} version={}", id, s->version());
        continue;
      }
    }
    if (s->idle_seconds() > limits_.idle_seconds && s->evict_if_unused()) {
      evict(id, *s, "idle");  // writes the record
      continue;
    }
    if (!shared && e.persisted_version != s->version()) persist(*s);
  }
  // Scratch kept for a burst of busy sessions goes once their mesh is idle.
  assets_.trim_idle_pools();
  if (collect_pending_.exchange(false)) collect_hierarchies();
}

void SessionRegistry::evict(const std::string& id, const Session& s, const char* why) {
  // s.evict_if_unused() came first: nothing changes it any more.
  persist(s);
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(id);
    if (it != sessions_.end() && it->second.session.get() == &s) {
      sessions_.erase(it);
      // Its record stays on this machine and a request loads it again: it
      // still counts against --max-sessions. (A shared store's other
      // replicas may serve it next; a memory-only store kept nothing.)
      if (!store_.shared() && store_.exists(id)) evicted_[id] = s.hierarchy_key();
    }
  }
  if (store_.shared()) {
    try {
      store_.release(id);
    } catch (const std::exception&) {  // the lease then simply expires
    }
  }
  spdlog::info("event=session_evicted session={} reason={} idle_seconds={:.0f}", id, why, s.idle_seconds());
}

std::size_t SessionRegistry::evict_idle_until(const std::function<bool()>& enough) {
  // Idle times read once: a session touched while sorting must not change the order.
  std::vector<std::pair<double, std::shared_ptr<Session>>> idle;
  for (auto& s : loaded())
    if (s->subscriber_count() == 0) idle.emplace_back(s->idle_seconds(), std::move(s));
  // The longest idle first: the least likely to be asked for again soon.
  std::sort(idle.begin(), idle.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::size_t evicted = 0;
  for (const auto& [seconds, s] : idle) {
    if (enough()) break;
    if (!s->evict_if_unused()) continue;  // a stream came meanwhile
    evict(s->id(), *s, "memory");
    ++evicted;
  }
  return evicted;
}

void SessionRegistry::shutdown() {
  for (const auto& s : loaded()) {
    persist(*s);
    s->persist_history();
    s->close_streams("the server is shutting down");
    if (store_.shared()) {
      try {
        store_.release(s->id());
      } catch (const std::exception&) {  // the lease then simply expires
      }
    }
  }
}

}  // namespace filigree::server
