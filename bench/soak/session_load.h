#pragma once
// One session under load: its own client connection (one engine), a paced
// driver and three watchers (normal, slow, reconnecting); at the end, the
// checks that the last pose reached the session and every watcher.

#include <array>
#include <chrono>
#include <memory>
#include <string>

#include "bench/soak/failures.h"
#include "bench/soak/options.h"
#include "bench/soak/paced_driver.h"
#include "bench/soak/soak_watcher.h"
#include "filigree/client.h"

namespace filigree::soak {

struct SessionSummary {
  DriverStats driver;
  std::array<WatcherStats, 3> watchers;  // by WatcherKind
  // Frames the session computed per second while driven (from the versions
  // the driver saw: every computed frame has a version).
  double fps = 0.0;
};

class SessionLoad {
 public:
  // `client` (a connection to `address`) and `session` outlive this.
  SessionLoad(Client& client, const std::string& address, const SessionHandle& session, int index, const Options& options,
              Failures& failures);
  ~SessionLoad();

  void start();
  // The driver stops posing and half-closes (every session at the same moment).
  void stop_posing();
  // Waits for the driver's end and checks that the last pose is reflected by
  // GetState and by every watcher's final frame; stops the watchers; closes
  // the session (OK expected).
  // Every session's waits share `deadline` (Options::end_limit after the last poses).
  void finish_and_check(std::chrono::steady_clock::time_point deadline);

  SessionSummary summary() const;
  std::uint64_t driver_frames() const { return driver_.stats().frames; }

 private:
  void check_state(std::uint64_t version, std::chrono::steady_clock::time_point deadline);

  Client& client_;
  const SessionHandle& session_;
  const Options& options_;
  Failures& failures_;
  // The slow watcher's connection: a 64 KiB stream window without BDP
  // probing, so that what it does not read backs up to the server (which
  // then skips frames for it) instead of in megabytes of HTTP/2 buffers.
  Client slow_client_;
  PacedDriver driver_;
  std::array<std::unique_ptr<SoakWatcher>, 3> watchers_;
};

}  // namespace filigree::soak
