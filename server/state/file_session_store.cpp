#include "server/state/file_session_store.h"

#include <fstream>
#include <mutex>
#include <optional>
#include <sstream>

namespace filigree::server {

FileSessionStore::FileSessionStore(std::filesystem::path dir) : dir_(std::move(dir)) {
  if (!dir_.empty()) std::filesystem::create_directories(dir_);
}

std::filesystem::path FileSessionStore::file_of(const std::string& id) const {
  if (dir_.empty() || !is_session_id(id)) return {};
  return dir_ / (id + ".session");
}

namespace {

std::filesystem::path progress_file(const std::filesystem::path& record_file) {
  std::filesystem::path p = record_file;
  return p.replace_extension(".progress");
}

// Write then rename: a crash leaves the old file, never half a new one.
void write_atomically(const std::filesystem::path& file, const std::string& bytes) {
  const auto tmp = std::filesystem::path(file.string() + ".partial");
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())))
      throw StoreUnavailable("cannot write " + tmp.string());
  }
  std::filesystem::rename(tmp, file);
}

std::optional<std::string> read_file(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  std::stringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

}  // namespace

bool FileSessionStore::create(const SessionRecord& r) {
  if (exists(r.id)) return false;
  return save(r);
}

bool FileSessionStore::save(const SessionRecord& r) {
  const auto file = file_of(r.id);
  if (file.empty()) return true;  // memory only
  std::lock_guard lock(write_mutex_);
  write_atomically(file, encode_session_record(r));
  // The record holds everything now; progress older than it is ignored on
  // load anyway, so a crash before this removal loses nothing.
  std::filesystem::remove(progress_file(file));
  return true;
}

bool FileSessionStore::save_progress(const std::string& id, const SessionProgress& p) {
  const auto file = file_of(id);
  if (file.empty()) return true;  // memory only
  const std::string bytes = encode_session_progress(p);
  // Under the lock, so that a session removed meanwhile gets no progress
  // file, whichever comes first.
  std::lock_guard lock(write_mutex_);
  if (!std::filesystem::exists(file)) return false;
  write_atomically(progress_file(file), bytes);
  return true;
}

std::optional<SessionRecord> FileSessionStore::load(const std::string& id) {
  const auto file = file_of(id);
  if (file.empty()) return std::nullopt;
  const std::optional<std::string> bytes = read_file(file);
  if (!bytes) return std::nullopt;
  SessionRecord r;
  try {
    r = decode_session_record(*bytes);
  } catch (const std::exception& e) {
    throw SessionUnusable("the record " + file.string() + " is unreadable: " + e.what());
  }
  const auto progress = progress_file(file);
  if (const std::optional<std::string> bytes = read_file(progress)) {
    SessionProgress p;
    try {
      p = decode_session_progress(*bytes);
    } catch (const std::exception& e) {
      throw SessionUnusable("the progress " + progress.string() + " is unreadable: " + e.what());
    }
    if (p.version >= r.version) apply_progress(p, r);
  }
  return r;
}

bool FileSessionStore::exists(const std::string& id) {
  const auto file = file_of(id);
  return !file.empty() && std::filesystem::exists(file);
}

void FileSessionStore::remove(const std::string& id) {
  const auto file = file_of(id);
  if (file.empty()) return;
  std::lock_guard lock(write_mutex_);
  std::filesystem::remove(progress_file(file));
  std::filesystem::remove(file);
}

std::vector<std::string> FileSessionStore::list() {
  std::vector<std::string> ids;
  if (dir_.empty()) return ids;
  for (const auto& entry : std::filesystem::directory_iterator(dir_))
    if (entry.path().extension() == ".session") ids.push_back(entry.path().stem().string());
  return ids;
}

}  // namespace filigree::server
