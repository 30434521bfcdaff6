#pragma once
// Whether the process can still open `n` more file descriptors. The two
// ports' acceptors keep a headroom this way so that gRPC's own accept
// (behind the ConnectionGuard) never meets EMFILE: gRPC 1.51 stops
// accepting for good when it does.
//
// Counted, not probed: opening n descriptors to see whether they fit took
// them from everyone else for that moment, so gRPC's accept could meet
// EMFILE while an acceptor merely looked (it did, under load, in a flood
// of connections). Counting /proc/self/fd holds one descriptor, briefly.

#include <cstddef>

#include <dirent.h>
#include <sys/resource.h>

namespace filigree::server {

// Descriptors this process has open (those counting it, the directory's
// own, excluded); 0 if /proc cannot be read.
inline std::size_t descriptors_open() {
  DIR* dir = ::opendir("/proc/self/fd");
  if (dir == nullptr) return 0;
  std::size_t n = 0;
  while (const dirent* e = ::readdir(dir)) n += e->d_name[0] != '.';
  ::closedir(dir);
  return n > 0 ? n - 1 : 0;
}

// Whether `n` more descriptors fit under the open-file limit (RLIMIT_NOFILE).
// True when the limit or /proc cannot be read (nothing to go by).
inline bool descriptors_free(std::size_t n) {
  rlimit limit{};
  if (::getrlimit(RLIMIT_NOFILE, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return true;
  const std::size_t open = descriptors_open();
  return open == 0 || open + n < static_cast<std::size_t>(limit.rlim_cur);
}

}  // namespace filigree::server
