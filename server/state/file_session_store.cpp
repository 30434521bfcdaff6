#include "server/state/file_session_store.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <mutex>

#include <fcntl.h>
#include <unistd.h>

#include <spdlog/spdlog.h>
#include <optional>
#include <sstream>

namespace filigree::server {

FileSessionStore::FileSessionStore(std::filesystem::path dir) : dir_(std::move(dir)) {
  if (dir_.empty()) return;
  // Records hold tokens: the folder is the server's user's alone (made so;
  // an existing one is warned about at start if others may write it).
  if (std::filesystem::create_directories(dir_))
    std::filesystem::permissions(dir_, std::filesystem::perms::owner_all, std::filesystem::perm_options::replace);
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

std::filesystem::path history_file(const std::filesystem::path& record_file) {
  std::filesystem::path p = record_file;
  return p.replace_extension(".history");
}

// Write, flush to the disk, then rename and flush the folder: a crash (of
// the process or the machine) leaves the old file or the new one, never half
// of one, and once this returns the new one is what a restart reads. Owner
// only (0600): records hold the session's tokens. Errors name the file's
// kind, not its path (they reach clients).
void write_durably(const std::filesystem::path& file, const std::string& bytes) {
  const auto tmp = std::filesystem::path(file.string() + ".partial");
  const auto fail = [&](const char* what) {
    throw StoreUnavailable(std::string("the session store cannot ") + what + ": " + std::strerror(errno));
  };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) fail("create a file");
  for (std::size_t at = 0; at < bytes.size();) {
    const ssize_t n = ::write(fd, bytes.data() + at, bytes.size() - at);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int error = errno;
      ::close(fd);
      errno = error;
      fail("write a file");
    }
    at += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0) {
    const int error = errno;
    ::close(fd);
    errno = error;
    fail("flush a file to disk");
  }
  ::close(fd);
  if (::rename(tmp.c_str(), file.c_str()) != 0) fail("rename a file");
  const int dir = ::open(file.parent_path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir < 0) fail("open its folder");
  const int synced = ::fsync(dir);
  ::close(dir);
  if (synced != 0) fail("flush its folder to disk");
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
  write_durably(file, encode_session_record(r));
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
  write_durably(progress_file(file), bytes);
  return true;
}

bool FileSessionStore::save_history(const std::string& id, const std::string& bytes) {
  const auto file = file_of(id);
  if (file.empty()) return true;  // memory only
  std::lock_guard lock(write_mutex_);
  if (!std::filesystem::exists(file)) return false;
  write_durably(history_file(file), bytes);
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
    // The path is for the operator's log; the client hears which session.
    spdlog::error("event=record_unreadable file=\"{}\" error=\"{}\"", file.string(), e.what());
    throw SessionUnusable("the stored record of session " + id + " is unreadable: " + e.what());
  }
  const auto progress = progress_file(file);
  if (const std::optional<std::string> bytes = read_file(progress)) {
    SessionProgress p;
    try {
      p = decode_session_progress(*bytes);
    } catch (const std::exception& e) {
      spdlog::error("event=record_unreadable file=\"{}\" error=\"{}\"", progress.string(), e.what());
      throw SessionUnusable("the stored progress of session " + id + " is unreadable: " + e.what());
    }
    if (p.version >= r.version) apply_progress(p, r);
  }
  if (std::optional<std::string> history = read_file(history_file(file))) r.history = std::move(*history);
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
  std::filesystem::remove(history_file(file));
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
