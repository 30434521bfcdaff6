#pragma once
// The gRPC port's PEM files (tls_files.h), re-read every refresh and handed to
// gRPC only once checked (tls_pair_check.h).
//
// gRPC 1.51 has no public way to push key material into a running server:
// its FileWatcherCertificateProvider reads files, and puts in force whatever
// it reads (an empty key file aborts the process; a garbage, expired or
// mismatched pair fails every handshake). So gRPC's watcher is pointed at
// files only this class writes: anonymous memory files (memfd_create) that
// hold the last good versions, reached as /proc/self/fd/N. A new good
// version replaces a memory file at once (dup3 onto the same descriptor
// number), so the watcher reads one whole version or the other; the key and
// the chain live in one memory file, so they can never be read from two
// versions. Nothing of the key is written to disk, and the memory files end
// with the process.
//
// A bad version of the operator's files keeps the pair in force and is
// logged at warn once, saying why; it is looked at again when the files
// change again.

#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "server/tls_files.h"

namespace filigree::server {

class VerifiedTlsFiles {
 public:
  // Reads and checks the files now. Throws std::runtime_error naming the
  // option, the file and what is wrong (never their contents). With
  // `watch`, a thread re-reads them every files.refresh_seconds.
  explicit VerifiedTlsFiles(const TlsFiles& files, bool watch = true);
  // Stops the thread. The credentials made from this object must be gone by
  // then (the memory files close with it).
  ~VerifiedTlsFiles();
  VerifiedTlsFiles(const VerifiedTlsFiles&) = delete;
  VerifiedTlsFiles& operator=(const VerifiedTlsFiles&) = delete;

  const TlsFiles& files() const { return files_; }

  // Paths gRPC's file watcher reads: the checked key and chain (one file for
  // both), and the checked CA bundles; empty when not configured.
  const std::string& identity_path() const { return identity_.path; }
  const std::string& client_ca_path() const { return client_ca_.path; }
  const std::string& peer_ca_path() const { return peer_ca_.path; }

  // Looks at the files now: those changed since the last look (by device,
  // inode, size or modification time) are read and checked; good ones are put
  // in force, a bad one is logged at warn and the previous version stays.
  // Returns whether everything now in force is what the files hold.
  bool refresh();

  // How often gRPC's watcher reads the memory files (cheap: no disk).
  static constexpr unsigned kGrpcReadSeconds = 1;

  struct Stamp {
    long long dev = -1, ino = -1, size = -1, mtime_ns = -1;
    bool operator==(const Stamp&) const = default;
  };

 private:
  // One memory file at a fixed descriptor number.
  struct MemoryFile {
    int fd = -1;
    std::string path;           // /proc/self/fd/<fd>
    long long last_second = 0;  // the modification time last given (seconds)
  };
  void put(MemoryFile& file, const std::string& bytes);
  bool refresh_identity();
  bool refresh_ca(const std::string& source, const char* option, MemoryFile& file, Stamp& stamp, bool& good);
  void watch_loop();

  const TlsFiles files_;
  std::mutex mutex_;  // refresh() from the thread and SIGHUP
  MemoryFile identity_, client_ca_, peer_ca_;
  std::vector<Stamp> identity_stamps_;  // of --tls-cert, --tls-key as last read
  Stamp client_ca_stamp_, peer_ca_stamp_;
  bool identity_good_ = true, client_ca_good_ = true, peer_ca_good_ = true;
  std::string subject_;  // of the certificate in force, for the log

  std::mutex stop_mutex_;
  std::condition_variable stop_cv_;
  bool stopping_ = false;
  std::thread thread_;
};

// The stamp of the file at `path` (all -1 if it cannot be stat'ed).
VerifiedTlsFiles::Stamp file_stamp(const std::string& path);

}  // namespace filigree::server
