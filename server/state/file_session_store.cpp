#include "server/state/file_session_store.h"

#include <fstream>
#include <sstream>

namespace filigree::server {

FileSessionStore::FileSessionStore(std::filesystem::path dir) : dir_(std::move(dir)) {
  if (!dir_.empty()) std::filesystem::create_directories(dir_);
}

std::filesystem::path FileSessionStore::file_of(const std::string& id) const {
  if (dir_.empty() || !is_session_id(id)) return {};
  return dir_ / (id + ".session");
}

bool FileSessionStore::create(const SessionRecord& r) {
  if (exists(r.id)) return false;
  return save(r);
}

bool FileSessionStore::save(const SessionRecord& r) {
  const auto file = file_of(r.id);
  if (file.empty()) return true;  // memory only
  // Write then rename: a crash leaves the old record, never half a new one.
  const auto tmp = std::filesystem::path(file.string() + ".partial");
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    const std::string bytes = encode_session_record(r);
    if (!out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())))
      throw StoreUnavailable("cannot write " + tmp.string());
  }
  std::filesystem::rename(tmp, file);
  return true;
}

bool FileSessionStore::save_progress(const std::string& id, const SessionProgress& p) {
  std::optional<SessionRecord> r = load(id);
  if (!r) return false;
  apply_progress(p, *r);
  return save(*r);
}

std::optional<SessionRecord> FileSessionStore::load(const std::string& id) {
  const auto file = file_of(id);
  if (file.empty()) return std::nullopt;
  std::ifstream in(file, std::ios::binary);
  if (!in) return std::nullopt;
  std::stringstream bytes;
  bytes << in.rdbuf();
  try {
    return decode_session_record(bytes.str());
  } catch (const std::exception& e) {
    throw SessionUnusable("the record " + file.string() + " is unreadable: " + e.what());
  }
}

bool FileSessionStore::exists(const std::string& id) {
  const auto file = file_of(id);
  return !file.empty() && std::filesystem::exists(file);
}

void FileSessionStore::remove(const std::string& id) {
  const auto file = file_of(id);
  if (!file.empty()) std::filesystem::remove(file);
}

std::vector<std::string> FileSessionStore::list() {
  std::vector<std::string> ids;
  if (dir_.empty()) return ids;
  for (const auto& entry : std::filesystem::directory_iterator(dir_))
    if (entry.path().extension() == ".session") ids.push_back(entry.path().stem().string());
  return ids;
}

}  // namespace filigree::server
