#include "server/verified_tls_files.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <ctime>
#include <stdexcept>
#include <system_error>

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/crypto.h>
#include <spdlog/spdlog.h>

#include "server/pem_file.h"
#include "server/tls_pair_check.h"

namespace filigree::server {
namespace {

// Wipes a string that held key material however the scope ends.
struct Cleansed {
  std::string& text;
  ~Cleansed() { OPENSSL_cleanse(text.data(), text.size()); }
};

void write_all(int fd, const std::string& bytes) {
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      throw std::system_error(errno, std::generic_category(), "writing a TLS memory file");
    }
    done += static_cast<std::size_t>(n);
  }
}

}  // namespace

VerifiedTlsFiles::Stamp file_stamp(const std::string& path) {
  struct stat st {};
  if (path.empty() || ::stat(path.c_str(), &st) != 0) return {};
  return {static_cast<long long>(st.st_dev), static_cast<long long>(st.st_ino), static_cast<long long>(st.st_size),
          static_cast<long long>(st.st_mtim.tv_sec) * 1'000'000'000LL + st.st_mtim.tv_nsec};
}

VerifiedTlsFiles::VerifiedTlsFiles(const TlsFiles& files, bool watch) : files_(files) {
  if (files_.cert.empty() || files_.key.empty()) throw std::runtime_error("--tls-cert and --tls-key go together");
  // Stamped before reading: a file replaced while being read shows as changed next time.
  identity_stamps_ = {file_stamp(files_.cert), file_stamp(files_.key)};
  {
    CheckedTlsPair pair = read_checked_tls_pair(files_.cert, files_.key);
    std::string both = pair.chain_pem + "\n" + pair.key_pem;
    const Cleansed cleanse{both};
    put(identity_, both);
    subject_ = pair.summary.subject;
    spdlog::info("event=tls_certificate reason=start subject=\"{}\" not_after=\"{}\" key=\"{}\"", pair.summary.subject,
                 pair.summary.not_after, pair.summary.key);
  }
  const auto ca = [this](const std::string& path, const char* option, MemoryFile& file, Stamp& stamp) {
    if (path.empty()) return;
    stamp = file_stamp(path);
    const std::string pem = read_pem(path, option);
    try {
      check_ca_bundle(pem);
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string(option) + " " + path + ": " + e.what());
    }
    put(file, pem);
  };
  ca(files_.client_ca, "--tls-client-ca", client_ca_, client_ca_stamp_);
  ca(files_.peer_ca, "--peer-ca", peer_ca_, peer_ca_stamp_);
  if (watch) thread_ = std::thread([this] { watch_loop(); });
}

VerifiedTlsFiles::~VerifiedTlsFiles() {
  {
    std::lock_guard lock(stop_mutex_);
    stopping_ = true;
  }
  stop_cv_.notify_all();
  if (thread_.joinable()) thread_.join();
  for (MemoryFile* f : {&identity_, &client_ca_, &peer_ca_})
    if (f->fd >= 0) ::close(f->fd);
}

void VerifiedTlsFiles::watch_loop() {
  const auto period = std::chrono::seconds(std::max(1u, files_.refresh_seconds));
  std::unique_lock lock(stop_mutex_);
  while (!stop_cv_.wait_for(lock, period, [this] { return stopping_; })) {
    lock.unlock();
    try {
      refresh();
    } catch (const std::exception& e) {
      // Out of memory or descriptors: the pair in force stays; try again next time.
      spdlog::warn("event=tls_files_check_failed error=\"{}\"", e.what());
    }
    lock.lock();
  }
}

void VerifiedTlsFiles::put(MemoryFile& file, const std::string& bytes) {
  const int fd = ::memfd_create("filigree-tls", MFD_CLOEXEC);
  if (fd < 0) throw std::system_error(errno, std::generic_category(), "memfd_create");
  try {
    if (::fchmod(fd, 0600) != 0) throw std::system_error(errno, std::generic_category(), "fchmod");
    write_all(fd, bytes);
    // gRPC's watcher compares modification times in whole seconds before and
    // after it reads: each version gets a later second than the one before,
    // so a read that straddles a replacement is always seen and retried.
    const long long now = static_cast<long long>(std::time(nullptr));
    const long long second = std::max(now, file.last_second + 1);
    const struct timespec times[2] = {{static_cast<time_t>(second), 0}, {static_cast<time_t>(second), 0}};
    if (::futimens(fd, times) != 0) throw std::system_error(errno, std::generic_category(), "futimens");
    if (file.fd < 0) {
      file.fd = fd;
      file.path = "/proc/self/fd/" + std::to_string(fd);
    } else {
      // One atomic step: the descriptor number (and so the path) now names the new file.
      if (::dup3(fd, file.fd, O_CLOEXEC) < 0) throw std::system_error(errno, std::generic_category(), "dup3");
      ::close(fd);
    }
    file.last_second = second;
  } catch (...) {
    if (fd != file.fd) ::close(fd);
    throw;
  }
}

bool VerifiedTlsFiles::refresh() {
  std::lock_guard lock(mutex_);
  const bool identity = refresh_identity();
  const bool client_ca = refresh_ca(files_.client_ca, "--tls-client-ca", client_ca_, client_ca_stamp_, client_ca_good_);
  const bool peer_ca = refresh_ca(files_.peer_ca, "--peer-ca", peer_ca_, peer_ca_stamp_, peer_ca_good_);
  return identity && client_ca && peer_ca;
}

bool VerifiedTlsFiles::refresh_identity() {
  std::vector<Stamp> seen = {file_stamp(files_.cert), file_stamp(files_.key)};
  if (seen == identity_stamps_) return identity_good_;
  identity_stamps_ = std::move(seen);
  try {
    CheckedTlsPair pair = read_checked_tls_pair(files_.cert, files_.key);
    std::string both = pair.chain_pem + "\n" + pair.key_pem;
    const Cleansed cleanse{both};
    put(identity_, both);
    subject_ = pair.summary.subject;
    identity_good_ = true;
    spdlog::info("event=tls_certificate reason=files_changed subject=\"{}\" not_after=\"{}\" key=\"{}\"",
                 pair.summary.subject, pair.summary.not_after, pair.summary.key);
  } catch (const std::exception& e) {
    // Once per change of the files: the stamps above are already the bad version's.
    identity_good_ = false;
    spdlog::warn("event=tls_certificate_rejected error=\"{}\" kept=\"{}\"", e.what(), subject_);
  }
  return identity_good_;
}

bool VerifiedTlsFiles::refresh_ca(const std::string& source, const char* option, MemoryFile& file, Stamp& stamp,
                                  bool& good) {
  if (source.empty()) return true;
  Stamp seen = file_stamp(source);
  if (seen == stamp) return good;
  stamp = seen;
  try {
    const std::string pem = read_pem(source, option);
    std::size_t count = 0;
    try {
      count = check_ca_bundle(pem);
    } catch (const std::exception& e) {
      throw std::runtime_error(std::string(option) + " " + source + ": " + e.what());
    }
    put(file, pem);
    good = true;
    spdlog::info("event=tls_ca_bundle reason=files_changed option={} certificates={}", option + 2, count);
  } catch (const std::exception& e) {
    good = false;
    spdlog::warn("event=tls_ca_bundle_rejected error=\"{}\" kept=previous", e.what());
  }
  return good;
}

}  // namespace filigree::server
