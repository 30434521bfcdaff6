// The soak (`make soak`, docs/deploy.md "Soak"): one filigree-server under a steady
// load for a set time, failing (exit 1, saying why) if it loses or reorders
// anything, refuses a malformed request with an unexpected code, fails any
// other call, or its memory grows after warm-up.
//
// Load: --sessions (16) sessions of one generated mesh; per session a driver
// posing at --rate-hz (30) and three watchers (normal, slow, reconnecting:
// SessionLoad, SoakWatcher); malformed requests on a connection of their own
// (MalformedRequests). Criteria and where they are checked:
//   versions never go backwards on any stream    PacedDriver, SoakWatcher
//   no acknowledged pose is lost                 PacedDriver (its header
//                                                defines it), SessionLoad
//   RSS after warm-up grows ≤ 5%                 judge_memory, below
//   every error is an expected one               MalformedRequests (codes),
//                                                every other call must succeed,
//                                                and SIGTERM must drain (exit 0)
//
// Usage: filigree_soak [--seconds N] [--sessions N] [--server PATH]
//        [--rate-hz HZ] [--memory-check=on|off]

#include <algorithm>
#include <condition_variable>
#include <csignal>
#include <mutex>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <thread>
#include <unistd.h>
#include <vector>

#include "bench/soak/crash_cycles.h"
#include "bench/soak/failures.h"
#include "bench/soak/malformed_requests.h"
#include "bench/soak/options.h"
#include "bench/soak/rss_sampler.h"
#include "bench/soak/session_load.h"
#include "bench/soak/soak_mesh.h"
#include "bench/soak/upload_pressure.h"
#include "filigree/client.h"
#include "support/server_process.h"

namespace {

using namespace filigree;
using namespace filigree::soak;
using Clock = std::chrono::steady_clock;

constexpr double kMemoryGrowthLimit = 0.05;

double mib(std::uint64_t bytes) { return static_cast<double>(bytes) / (1024.0 * 1024.0); }
double seconds_since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Warm-up: the first 20% of the run, at least 30 s (allocator arenas, gRPC
// buffers and the sessions' caches fill up before memory settles).
double warmup_seconds(double run_seconds) { return std::max(0.2 * run_seconds, 30.0); }

struct Totals {
  std::uint64_t poses_sent = 0, acknowledged = 0, driver_frames = 0;
  std::uint64_t watcher_frames[3] = {}, skipped[3] = {}, reconnects = 0, slow_max_lag = 0;
  double fps_min = 0.0, fps_mean = 0.0;
};

Totals add_up(const std::vector<std::unique_ptr<SessionLoad>>& loads) {
  Totals t;
  double fps_sum = 0.0;
  t.fps_min = loads.empty() ? 0.0 : 1e300;
  for (const auto& load : loads) {
    const SessionSummary s = load->summary();
    t.poses_sent += s.driver.poses_sent;
    t.acknowledged += s.driver.acknowledged;
    t.driver_frames += s.driver.frames;
    for (int k = 0; k < 3; ++k) {
      t.watcher_frames[k] += s.watchers[k].frames;
      t.skipped[k] += s.watchers[k].skipped;
      t.reconnects += s.watchers[k].reconnects;
      t.slow_max_lag = std::max(t.slow_max_lag, s.watchers[k].max_lag);
    }
    fps_sum += s.fps;
    t.fps_min = std::min(t.fps_min, s.fps);
  }
  t.fps_mean = loads.empty() ? 0.0 : fps_sum / static_cast<double>(loads.size());
  return t;
}

void print_summary(const Options& o, double driven, const SoakMesh& mesh, std::size_t base_vertices, const Totals& t,
                   const std::vector<MalformedTally>& malformed, const MemoryVerdict& memory, double server_cores, int exit_status,
                   const CrashCycleSummary& crashes, const UploadPressureSummary& uploads, const Failures& failures) {
  std::printf("\n== filigree soak summary ==\n");
  std::printf("duration        %.1f s driven (asked %.0f s), %d sessions, poses at %.0f Hz\n", driven, o.seconds,
              o.sessions, o.rate_hz);
  std::printf("mesh            icosphere, %zu vertices, %zu faces (base %zu vertices)\n", mesh.vertices, mesh.faces,
              base_vertices);
  std::printf("poses           sent %llu, acknowledged %llu (a frame named them or a later pose)\n",
              static_cast<unsigned long long>(t.poses_sent), static_cast<unsigned long long>(t.acknowledged));
  std::printf("frames          drivers %llu; watchers normal %llu, slow %llu (%llu versions skipped), reconnecting %llu\n",
              static_cast<unsigned long long>(t.driver_frames), static_cast<unsigned long long>(t.watcher_frames[0]),
              static_cast<unsigned long long>(t.watcher_frames[1]), static_cast<unsigned long long>(t.skipped[1]),
              static_cast<unsigned long long>(t.watcher_frames[2]));
  std::printf("slow watchers   at most %llu versions behind the driver when reading (default channel, Follow)\n",
              static_cast<unsigned long long>(t.slow_max_lag));
  std::printf("reconnects      %llu (every %.0f s, resumed with after_version)\n",
              static_cast<unsigned long long>(t.reconnects), o.reconnect_every.count() / 1000.0);
  std::uint64_t sent = 0;
  for (const MalformedTally& m : malformed) sent += m.sent;
  std::printf("malformed       %llu requests\n", static_cast<unsigned long long>(sent));
  for (const MalformedTally& m : malformed) {
    std::string got;
    for (const auto& [code, n] : m.got)
      got += (got.empty() ? "" : ", ") + std::to_string(n) + " × " + status_code_name(code);
    std::printf("  %-46s expected %-17s got %s\n", m.kind.c_str(), status_code_name(m.expected),
                got.empty() ? "-" : got.c_str());
  }
  if (memory.judged)
    std::printf("server RSS      warm-up end (%.0f s) %.1f MiB, max %.1f MiB, end %.1f MiB; growth %+.2f%% (max %+.2f%%), "
                "limit %.0f%%%s\n",
                memory.warmup_seconds, mib(memory.warmup_end), mib(memory.max), mib(memory.end), 100.0 * memory.growth,
                100.0 * memory.max_growth, 100.0 * kMemoryGrowthLimit, o.memory_check ? "" : " [not judged: --memory-check=off]");
  else
    std::printf("server RSS      warm-up end (%.0f s) not reached, max %.1f MiB, end %.1f MiB [%s]\n", memory.warmup_seconds,
                mib(memory.max), mib(memory.end), o.memory_check ? "too short to judge" : "not judged: --memory-check=off");
  std::printf("session fps     min %.1f, mean %.1f (frames computed per second per session)\n", t.fps_min, t.fps_mean);
  std::printf("server CPU      %.2f cores on average while driven\n", server_cores);
  std::printf("server exit     %d on SIGTERM (0: drained)\n", exit_status);
  std::printf("crash cycles    %d SIGKILL/restart cycles, %llu acknowledged poses, %llu sessions checked after restarts; "
              "slowest restart %.2f s\n",
              crashes.cycles, static_cast<unsigned long long>(crashes.acknowledged),
              static_cast<unsigned long long>(crashes.checks), crashes.slowest_restart_seconds);
  if (uploads.uploads)
    std::printf("upload burst    %d concurrent uploads of %d MiB under --max-memory %llu MiB: %d created, %d refused; "
                "peak RSS %.1f MiB\n",
                uploads.uploads, o.upload_mib, static_cast<unsigned long long>(uploads.limit_bytes >> 20), uploads.created,
                uploads.refused, mib(uploads.peak_rss_bytes));
  const auto reasons = failures.reasons();
  if (failures.count() == 0) {
    std::printf("RESULT: PASS\n");
  } else {
    std::printf("RESULT: FAIL (%zu failures%s)\n", failures.count(),
                failures.count() > reasons.size() ? ", the first ones:" : ":");
    for (const std::string& r : reasons) std::printf("  - %s\n", r.c_str());
  }
  std::fflush(stdout);
}

// SIGTERM drains the server (streams end, records are written) and it exits
// 0. One that does not exit within `limit` is killed (SIGKILL, this
// program's own child, by pid) so that the soak ends and says so.
int terminate_within(test::ServerProcess& server, std::chrono::seconds limit, Failures& failures) {
  const int pid = server.pid();
  std::mutex mutex;
  std::condition_variable done_cv;
  bool done = false;
  std::thread watchdog([&] {
    std::unique_lock lock(mutex);
    if (done_cv.wait_for(lock, limit, [&] { return done; })) return;
    failures.add("filigree-server did not exit within " + std::to_string(limit.count()) + " s of SIGTERM: killed");
    ::kill(pid, SIGKILL);
  });
  const int status = server.terminate();
  {
    std::lock_guard lock(mutex);
    done = true;
  }
  done_cv.notify_all();
  watchdog.join();
  return status;
}

int run(const Options& o) {
  Failures failures;
  const SoakMesh mesh = soak_mesh(o.sphere_levels);
  std::printf("filigree soak: %d sessions × (driver at %.0f Hz + normal, slow, reconnecting watcher) for %.0f s; "
              "mesh: icosphere of %zu vertices\n",
              o.sessions, o.rate_hz, o.seconds, mesh.vertices);

  // Sessions are journaled under a data dir, as a deployed server does.
  const auto data_dir = std::filesystem::temp_directory_path() / ("filigree_soak_" + std::to_string(::getpid()));
  std::filesystem::create_directories(data_dir);
  struct RemoveDir {
    std::filesystem::path p;
    ~RemoveDir() {
      std::error_code ignored;
      std::filesystem::remove_all(p, ignored);
    }
  } remove_dir{data_dir};
  test::ServerProcess server(o.server, {"--data-dir", data_dir.string()});
  std::printf("server %s (pid %d) on %s\n", o.server.c_str(), server.pid(), server.address().c_str());

  // One client (connection) per session, as each would be its own engine.
  std::vector<std::unique_ptr<Client>> clients;
  std::vector<SessionHandle> sessions;
  sessions.reserve(static_cast<std::size_t>(o.sessions));  // SessionLoad holds references
  const auto upload_start = Clock::now();
  for (int i = 0; i < o.sessions; ++i) {
    clients.push_back(std::make_unique<Client>(server.address()));
    sessions.push_back(clients.back()->create_session(mesh.obj, "obj", {}, "soak"));
    if (i == 0) std::printf("first upload (preprocessing) %.2f s; ", seconds_since(upload_start));
  }
  std::printf("%d sessions in %.2f s; base %zu vertices\n", o.sessions, seconds_since(upload_start),
              sessions[0].mesh.base_vertex_count());

  std::vector<std::unique_ptr<SessionLoad>> loads;
  std::vector<const SessionHandle*> targets;
  for (int i = 0; i < o.sessions; ++i) {
    loads.push_back(std::make_unique<SessionLoad>(*clients[i], server.address(), sessions[i], i, o, failures));
    targets.push_back(&sessions[i]);
  }
  RssSampler rss(server.pid(), o.rss_every, failures);
  MalformedRequests malformed(server.address(), targets, o.malformed_every, failures);
  const auto start = Clock::now();
  const double cpu_start = cpu_seconds(server.pid());
  rss.start();
  for (auto& load : loads) load->start();
  malformed.start();

  // The run's length is the workload, so the main thread just waits it out,
  // telling how it goes now and then.
  const auto end = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.seconds));
  const auto every = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::clamp(o.seconds / 10.0, 5.0, 30.0)));
  for (auto next = start + every; next < end; next += every) {
    std::this_thread::sleep_until(next);
    if (resident_bytes(server.pid()) == 0) break;  // the server died (a failure already): no point going on
    std::uint64_t frames = 0;
    for (const auto& load : loads) frames += load->driver_frames();
    std::printf("[%5.0f s] server RSS %.1f MiB, driver frames %llu, failures %zu\n", seconds_since(start),
                mib(rss.latest_bytes()), static_cast<unsigned long long>(frames), failures.count());
    std::fflush(stdout);
  }
  if (resident_bytes(server.pid()) != 0) std::this_thread::sleep_until(end);

  // The end: every driver's last pose at once, no more malformed requests
  // (the one in flight answered: none may change a session after that),
  // the last memory sample, then the checks.
  for (auto& load : loads) load->stop_posing();
  const double driven = seconds_since(start);
  malformed.stop();
  rss.stop();
  const double server_cores = (cpu_seconds(server.pid()) - cpu_start) / seconds_since(start);
  const auto end_deadline = Clock::now() + o.end_limit;
  for (auto& load : loads) load->finish_and_check(end_deadline);
  const int exit_status = terminate_within(server, std::chrono::seconds(60), failures);
  if (exit_status != 0) failures.add("filigree-server exited with " + std::to_string(exit_status) + " on SIGTERM (0: drained)");

  CrashCycleSummary crashes;
  if (o.crash_cycles > 0) {
    std::printf("crash cycles: %d × (4 sessions driven at %.0f Hz, SIGKILL, restart, checks)\n", o.crash_cycles, o.rate_hz);
    std::fflush(stdout);
    crashes = run_crash_cycles(o.server, soak_mesh(3), 4, o.crash_cycles, o.rate_hz, 1.5, failures);
  }
  UploadPressureSummary uploads;
  if (o.upload_mib > 0) {
    std::printf("upload burst: 8 × %d MiB at once under --max-memory %d MiB\n", o.upload_mib, 4 * o.upload_mib);
    std::fflush(stdout);
    uploads = run_upload_pressure(o.server, 8, o.upload_mib, 4 * o.upload_mib, failures);
  }

  const MemoryVerdict memory = judge_memory(rss.samples(), warmup_seconds(o.seconds));
  if (o.memory_check) {
    if (!memory.judged) {
      failures.add("the run is too short to judge memory (warm-up " + std::to_string(static_cast<int>(memory.warmup_seconds)) +
                   " s): run longer, or pass --memory-check=off");
    } else if (memory.growth > kMemoryGrowthLimit) {
      char why[200];
      std::snprintf(why, sizeof why, "server RSS grew %.2f%% after warm-up (%.1f → %.1f MiB), over the %.0f%% limit",
                    100.0 * memory.growth, mib(memory.warmup_end), mib(memory.end), 100.0 * kMemoryGrowthLimit);
      failures.add(why);
    }
  }
  print_summary(o, driven, mesh, sessions[0].mesh.base_vertex_count(), add_up(loads), malformed.tallies(), memory,
                server_cores, exit_status, crashes, uploads, failures);
  return failures.count() == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  Options options;
  try {
    options = parse_options(argc, argv);
  } catch (const std::invalid_argument& e) {
    if (*e.what()) std::fprintf(stderr, "filigree_soak: %s\n", e.what());
    std::fputs(usage().c_str(), stderr);
    return 2;
  }
  try {
    return run(options);
  } catch (const std::exception& e) {
    std::printf("RESULT: FAIL (%s)\n", e.what());
    return 1;
  }
}
