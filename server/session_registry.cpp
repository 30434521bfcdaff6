#include "server/session_registry.h"

#include <fstream>
#include <random>

#include <spdlog/spdlog.h>

#include "filigree/internal/session_record.pb.h"

namespace filigree::server {

std::string random_token() {
  static thread_local std::random_device device;
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  for (int i = 0; i < 4; ++i) {
    std::uint32_t bits = device();
    for (int k = 0; k < 8; ++k, bits >>= 4) out += kHex[bits & 15];
  }
  return out;
}

SessionRegistry::SessionRegistry(HierarchyCache& cache, std::filesystem::path data_dir, RegistryLimits limits)
    : cache_(cache), dir_(data_dir.empty() ? data_dir : data_dir / "sessions"), limits_(limits) {
  if (!dir_.empty()) std::filesystem::create_directories(dir_);
}

SessionRegistry::~SessionRegistry() = default;

std::filesystem::path SessionRegistry::record_file(const std::string& id) const { return dir_ / (id + ".session"); }

std::shared_ptr<Session> SessionRegistry::create(std::shared_ptr<const Hierarchy> h, const std::string& hierarchy_key,
                                                 const v1::SessionOptions& options, std::vector<Index> uploaded_ids) {
  {
    std::lock_guard lock(mutex_);
    if (sessions_.size() >= limits_.max_sessions)
      throw TooManySessions("the server holds its maximum of " + std::to_string(limits_.max_sessions) + " sessions");
  }
  SessionRecord r;
  r.id = random_token().substr(0, 20);
  r.hierarchy_key = hierarchy_key;
  r.options = options;
  r.editor_token = random_token();
  r.viewer_token = random_token();
  r.uploaded_ids = std::move(uploaded_ids);
  auto s = std::make_shared<Session>(std::move(r), std::move(h));
  persist(*s);
  std::lock_guard lock(mutex_);
  sessions_[s->id()] = s;
  spdlog::info("event=session_created session={} key={}", s->id(), hierarchy_key);
  return s;
}

std::shared_ptr<Session> SessionRegistry::find(const std::string& id) {
  {
    std::lock_guard lock(mutex_);
    const auto it = sessions_.find(id);
    if (it != sessions_.end()) return it->second;
  }
  // Evicted (or never loaded): its record may be on disk. Ids are hex, so the
  // file name cannot escape the directory.
  if (dir_.empty() || id.empty() || id.find_first_not_of("0123456789abcdef") != std::string::npos) return nullptr;
  const auto file = record_file(id);
  if (!std::filesystem::exists(file)) return nullptr;
  return load_record(file);
}

bool SessionRegistry::close(const std::string& id) {
  std::shared_ptr<Session> s = find(id);
  if (!s) return false;
  {
    std::lock_guard lock(mutex_);
    sessions_.erase(id);
    persisted_version_.erase(id);
  }
  s->close();
  if (!dir_.empty()) std::filesystem::remove(record_file(id));
  spdlog::info("event=session_closed session={}", id);
  return true;
}

std::vector<std::shared_ptr<Session>> SessionRegistry::loaded() const {
  std::lock_guard lock(mutex_);
  std::vector<std::shared_ptr<Session>> out;
  for (const auto& [id, s] : sessions_) out.push_back(s);
  return out;
}

void SessionRegistry::persist(const Session& s) {
  if (dir_.empty()) return;
  const SessionRecord r = s.record();
  internal::SessionRecord p;
  p.set_format_version(1);
  p.set_session_id(r.id);
  p.set_hierarchy_key(r.hierarchy_key);
  *p.mutable_options() = r.options;
  p.set_editor_token(r.editor_token);
  p.set_viewer_token(r.viewer_token);
  for (float c : r.pose) p.add_pose(c);
  p.set_version(r.version);
  for (Index v : r.uploaded_ids) p.add_uploaded_ids(v);
  // Write then rename: a crash leaves the old record, never half a new one.
  const auto file = record_file(r.id);
  const auto tmp = std::filesystem::path(file.string() + ".partial");
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out || !p.SerializeToOstream(&out)) {
      spdlog::error("event=persist_failed session={} file={}", r.id, tmp.string());
      return;
    }
  }
  std::filesystem::rename(tmp, file);
  std::lock_guard lock(mutex_);
  persisted_version_[r.id] = r.version;
}

std::shared_ptr<Session> SessionRegistry::load_record(const std::filesystem::path& file) {
  internal::SessionRecord p;
  {
    std::ifstream in(file, std::ios::binary);
    if (!in || !p.ParseFromIstream(&in) || p.format_version() != 1) {
      spdlog::error("event=record_unreadable file={}", file.string());
      return nullptr;
    }
  }
  SessionRecord r;
  r.id = p.session_id();
  r.hierarchy_key = p.hierarchy_key();
  r.options = p.options();
  r.editor_token = p.editor_token();
  r.viewer_token = p.viewer_token();
  r.pose.assign(p.pose().begin(), p.pose().end());
  r.version = p.version();
  r.uploaded_ids.assign(p.uploaded_ids().begin(), p.uploaded_ids().end());
  std::shared_ptr<Session> s;
  try {
    s = std::make_shared<Session>(std::move(r), cache_.load(p.hierarchy_key()));
  } catch (const std::exception& e) {
    spdlog::error("event=record_unusable file={} error=\"{}\"", file.string(), e.what());
    return nullptr;
  }
  std::lock_guard lock(mutex_);
  const auto [it, inserted] = sessions_.emplace(s->id(), s);
  persisted_version_[s->id()] = s->version();
  if (inserted) spdlog::info("event=session_loaded session={} version={}", s->id(), s->version());
  return it->second;
}

std::size_t SessionRegistry::restore() {
  if (dir_.empty()) return 0;
  std::size_t n = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir_))
    if (entry.path().extension() == ".session" && load_record(entry.path())) ++n;
  return n;
}

void SessionRegistry::maintain() {
  for (const auto& s : loaded()) {
    bool changed;
    {
      std::lock_guard lock(mutex_);
      changed = persisted_version_[s->id()] != s->version();
    }
    if (changed) persist(*s);
    if (s->subscriber_count() == 0 && s->idle_seconds() > limits_.idle_seconds) {
      persist(*s);
      std::lock_guard lock(mutex_);
      sessions_.erase(s->id());
      spdlog::info("event=session_evicted session={} idle_seconds={:.0f}", s->id(), s->idle_seconds());
    }
  }
}

void SessionRegistry::shutdown() {
  for (const auto& s : loaded()) {
    persist(*s);
    s->close_streams();
  }
}

}  // namespace filigree::server
