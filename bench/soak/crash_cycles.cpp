#include "bench/soak/crash_cycles.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <unistd.h>

#include "filigree/client.h"
#include "support/server_process.h"

namespace filigree::soak {
namespace {

using Clock = std::chrono::steady_clock;

// Pose `n` of a session moves base vertex 0 by n·kStep along x from rest:
// each pose further than the one before.
constexpr float kStep = 1e-5f;

std::vector<float> pose_of(const std::vector<float>& rest, std::uint64_t n) {
  std::vector<float> p = rest;
  p[0] = rest[0] + kStep * static_cast<float>(n);
  return p;
}

// One session's drive until the server dies: poses at a fixed rate on one
// thread, frames read on another; what the frames acknowledged.
struct CycleDrive {
  std::uint64_t acknowledged = 0;  // newest pose a frame named (the session's pose counter)
  std::uint64_t acknowledged_poses = 0;  // of this cycle
  std::uint64_t newest_version = 0;
};

CycleDrive drive_until_killed(Client& client, const SessionHandle& s, std::uint64_t& counter, double rate_hz,
                              std::atomic<bool>& killed) {
  Reconnect none;
  none.enabled = false;
  auto driver = client.drive(s.session_id, s.editor_token, "crash-cycles", none);
  CycleDrive out;
  const std::uint64_t first = counter + 1;
  std::thread reader([&] {
    while (auto frame = driver->read()) {
      // Pose ids on this stream are 1, 2, … for the counter's first + 0, 1, …
      if (frame->pose_id() > 0) out.acknowledged = std::max(out.acknowledged, first + frame->pose_id() - 1);
      out.newest_version = std::max(out.newest_version, frame->version());
    }
  });
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1.0 / rate_hz));
  auto next = Clock::now();
  for (std::uint64_t id = 1; !killed; ++id) {
    ++counter;
    if (!driver->send(id, pose_of(s.mesh.base_positions, counter))) break;
    next += period;
    std::this_thread::sleep_until(next);  // the drive's pace
  }
  reader.join();
  driver->cancel();
  out.acknowledged_poses = out.acknowledged >= first ? out.acknowledged - first + 1 : 0;
  return out;
}

}  // namespace

CrashCycleSummary run_crash_cycles(const std::string& server_binary, const SoakMesh& mesh, int sessions, int cycles,
                                   double rate_hz, double drive_seconds, Failures& failures) {
  CrashCycleSummary summary;
  const auto dir = std::filesystem::temp_directory_path() / ("filigree_soak_crash_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::vector<std::string> args = {"--data-dir", dir.string()};
  auto server = std::make_unique<test::ServerProcess>(server_binary, args);
  std::vector<SessionHandle> handles;
  {
    Client setup(server->address());
    for (int i = 0; i < sessions; ++i) handles.push_back(setup.create_session(mesh.obj, "obj", {}, "crash-cycles"));
  }
  std::vector<std::uint64_t> counters(handles.size(), 0);
  for (int cycle = 1; cycle <= cycles; ++cycle) {
    std::atomic<bool> killed{false};
    std::vector<CycleDrive> drives(handles.size());
    std::vector<std::unique_ptr<Client>> clients;
    std::vector<std::thread> threads;
    for (std::size_t i = 0; i < handles.size(); ++i) {
      clients.push_back(std::make_unique<Client>(server->address()));
      threads.emplace_back([&, i] { drives[i] = drive_until_killed(*clients[i], handles[i], counters[i], rate_hz, killed); });
    }
    // The workload's length, then the crash: in the middle of the drive.
    std::this_thread::sleep_for(std::chrono::duration<double>(drive_seconds));
    const auto kill_at = Clock::now();
    server->kill_now();
    killed = true;
    for (auto& t : threads) t.join();
    clients.clear();
    server = std::make_unique<test::ServerProcess>(server_binary, args);
    summary.slowest_restart_seconds =
        std::max(summary.slowest_restart_seconds, std::chrono::duration<double>(Clock::now() - kill_at).count());
    Client after(server->address());
    for (std::size_t i = 0; i < handles.size(); ++i) {
      const SessionHandle& s = handles[i];
      const CycleDrive& d = drives[i];
      summary.acknowledged += d.acknowledged_poses;
      const std::string where = "crash cycle " + std::to_string(cycle) + ", session " + s.session_id + ": ";
      try {
        const v1::SessionState state = after.state(s.session_id, s.viewer_token);
        if (state.version() < d.newest_version)
          failures.add(where + "restored at version " + std::to_string(state.version()) + ", but a frame of version " +
                       std::to_string(d.newest_version) + " was seen before the kill");
        const float acknowledged_x = pose_of(s.mesh.base_positions, d.acknowledged)[0];
        if (state.pose_size() == 0 || state.pose(0) < acknowledged_x)
          failures.add(where + "the stored pose is older than pose " + std::to_string(d.acknowledged) +
                       ", which a frame acknowledged before the kill");
        // The next frame's version was never given out before.
        Reconnect none;
        none.enabled = false;
        auto driver = after.drive(s.session_id, s.editor_token, "crash-cycles", none);
        ++counters[i];
        driver->send(1, pose_of(s.mesh.base_positions, counters[i]));
        std::optional<v1::Frame> frame;
        while ((frame = driver->read()) && frame->pose_id() < 1) {
        }
        if (!frame)
          failures.add(where + "no frame answered a pose after the restart");
        else if (frame->version() <= d.newest_version)
          failures.add(where + "a frame after the restart has version " + std::to_string(frame->version()) +
                       ", one seen before the kill (" + std::to_string(d.newest_version) + " was)");
        driver->cancel();
        ++summary.checks;
      } catch (const std::exception& e) {
        failures.add(where + e.what());
      }
    }
    ++summary.cycles;
  }
  server->terminate();
  std::error_code ignored;
  std::filesystem::remove_all(dir, ignored);
  return summary;
}

}  // namespace filigree::soak
