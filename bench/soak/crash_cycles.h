#pragma once
// The soak's crash phase: a server under --data-dir is killed (SIGKILL) while
// its sessions are driven, and started again on the same data dir, a few
// times. After each restart, for every session:
//   no acknowledged pose is lost    the stored pose is the newest pose a frame
//                                   named before the kill, or a later one sent
//                                   (poses move one base vertex monotonically,
//                                   so "later" is "further");
//   versions never go back          the restored version is at least the
//                                   newest any frame had before the kill;
//   versions never repeat           the first new frame's version is newer
//                                   than any frame seen before the kill.

#include <string>

#include "bench/soak/failures.h"
#include "bench/soak/soak_mesh.h"

namespace filigree::soak {

struct CrashCycleSummary {
  int cycles = 0;
  std::uint64_t acknowledged = 0;  // poses a frame named before a kill, over every session and cycle
  std::uint64_t checks = 0;        // sessions checked after a restart
  double slowest_restart_seconds = 0.0;  // from the kill to the restarted server listening
};

// `sessions` sessions driven at `rate_hz`, each cycle for `drive_seconds`
// before the kill.
CrashCycleSummary run_crash_cycles(const std::string& server_binary, const SoakMesh& mesh, int sessions, int cycles,
                                   double rate_hz, double drive_seconds, Failures& failures);

}  // namespace filigree::soak
