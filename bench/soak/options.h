#pragma once
// The soak's command line.

#include <chrono>
#include <string>

namespace filigree::soak {

struct Options {
  double seconds = 600.0;  // how long the sessions are driven
  int sessions = 16;
  std::string server;      // the filigree-server binary
  double rate_hz = 30.0;   // poses per second per driver
  // Off for runs too short to judge memory (the ctest smoke run); every other
  // criterion still applies.
  bool memory_check = true;
  // After the load: SIGKILL/restart cycles (crash_cycles.h), and concurrent
  // uploads of upload_mib MiB each under --max-memory (upload_pressure.h).
  int crash_cycles = 3;
  int upload_mib = 64;

  // The workload's shape (not options: the issue fixes them).
  int sphere_levels = 5;  // icosphere of 10242 vertices: 16 sessions × 30 Hz fit on 2 cores
  std::chrono::milliseconds slow_reader_delay{150};  // > the 33 ms between frames: it must skip
  std::chrono::milliseconds reconnect_every{3000};
  std::chrono::milliseconds malformed_every{100};
  std::chrono::milliseconds rss_every{2000};
  // After the last poses, how long every session's final frames and checks
  // may take in all before what is missing counts as lost. A bound for a hung
  // server, not a timing assertion: on a healthy one they take milliseconds.
  std::chrono::seconds end_limit{120};
};

// Throws std::invalid_argument saying what is wrong (the caller prints usage()).
Options parse_options(int argc, char** argv);
std::string usage();

}  // namespace filigree::soak
