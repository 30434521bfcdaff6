#pragma once
// Whether the process can still open `n` more file descriptors, found by
// opening them (dup of `any_open`) and closing them again. The two ports'
// acceptors keep a headroom this way so that gRPC's own accept (behind the
// ConnectionGuard) never meets EMFILE: gRPC 1.51 stops accepting for good
// when it does.

#include <array>
#include <cstddef>

#include <unistd.h>

namespace filigree::server {

// At most 64 probed; `any_open` must be an open descriptor.
inline bool descriptors_free(int any_open, std::size_t n) {
  std::array<int, 64> probe;
  probe.fill(-1);
  if (n > probe.size()) n = probe.size();
  bool room = true;
  for (std::size_t i = 0; i < n && room; ++i) room = (probe[i] = ::dup(any_open)) >= 0;
  for (const int fd : probe)
    if (fd >= 0) ::close(fd);
  return room;
}

}  // namespace filigree::server
