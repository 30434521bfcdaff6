#pragma once
// Session records as files under <data-dir>/sessions/ (one machine): this
// process owns every session, so claims always succeed. Every write is
// flushed to disk before it returns (the session journal: DESIGN §3.3).
// <id>.session holds the whole record as created (or last saved whole);
// <id>.progress what changed since (SessionProgress), written alone so that a
// busy session does not rewrite what never changes (the upload's ids: a
// 1.25M-vertex session wrote ~4 MB a second). A load applies the progress
// unless it is older than the record.

#include <filesystem>
#include <mutex>

#include "server/state/session_store.h"

namespace filigree::server {

class FileSessionStore final : public SessionStore {
 public:
  // `dir` empty: nothing is kept (memory only).
  explicit FileSessionStore(std::filesystem::path dir);

  bool shared() const override { return false; }
  bool persistent() const override { return !dir_.empty(); }
  bool create(const SessionRecord& r) override;
  bool save(const SessionRecord& r) override;
  bool save_progress(const std::string& id, const SessionProgress& p) override;
  bool save_history(const std::string& id, const std::string& bytes) override;
  std::optional<SessionRecord> load(const std::string& id) override;
  bool exists(const std::string& id) override;
  void remove(const std::string& id) override;
  std::vector<std::string> list() override;
  Claim claim(const std::string&, bool) override {
    Claim c;
    c.acquired = true;
    return c;
  }
  Renewal renew(const std::string&, bool) override { return Renewal::kHeld; }
  void release(const std::string&) override {}

 private:
  // Empty for an id that is not a session id (hex only: no path escapes).
  std::filesystem::path file_of(const std::string& id) const;
  const std::filesystem::path dir_;
  // Orders writes and removals: the maintenance loop may save a session's
  // progress while it is being closed.
  std::mutex write_mutex_;
};

}  // namespace filigree::server
