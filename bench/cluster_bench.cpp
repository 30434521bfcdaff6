// Replicas benchmark on loopback (issue 6), what sharing state costs and what
// a failure costs:
//   1. pose → frame latency (closed loop) on one server alone, on a replica
//      journaling every pose to Redis, and through nginx to that replica;
//   2. a hierarchy built by one replica against loaded from Redis by another;
//   3. failover: from SIGKILL of the replica that serves a driven session to
//      the first frame acknowledged by the replica that took it over, for two
//      lease lengths.
// Meshes: the shipped Armadillo (26k vertices).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <thread>

#include "bench/sample_stats.h"
#include "filigree/client.h"
#include "support/cluster.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace {

using namespace filigree;
using bench::percentile;
using Clock = std::chrono::steady_clock;

double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

std::vector<float> pose(const SessionMesh& mesh, std::uint64_t i) {
  std::vector<float> p = mesh.base_positions;
  for (std::size_t v = 0; v < p.size() / 3; ++v)
    p[3 * v] += 2.0f * std::sin(0.15f * static_cast<float>(i) + 0.05f * mesh.base_positions[3 * v + 1]);
  return p;
}

// Sends poses first..last lock-step; returns each pose → frame latency in ms.
std::vector<double> drive(Client& client, const SessionHandle& s, std::uint64_t first, std::uint64_t last) {
  std::vector<double> ms;
  auto driver = client.drive(s.session_id, s.editor_token, "bench");
  for (std::uint64_t i = first; i <= last; ++i) {
    const auto t = Clock::now();
    if (!driver->send(i, pose(s.mesh, i))) break;
    std::optional<v1::Frame> f;
    while ((f = driver->read()) && f->pose_id() < i) {
    }
    if (!f) break;
    ms.push_back(ms_since(t));
  }
  driver->writes_done();
  driver->finish();
  return ms;
}

void latency_row(const char* name, const std::vector<double>& ms, double baseline_p50) {
  const double p50 = percentile(ms, 0.5), p99 = percentile(ms, 0.99);
  std::printf("| %s | %zu | %.2f | %.2f | %.2f |\n", name, ms.size(), p50, p99, baseline_p50 > 0 ? p50 / baseline_p50 : 1.0);
}

}  // namespace

int main() {
  const std::string mesh = test::file_bytes(std::string(FILIGREE_REPO_DATA_DIR) + "/armadillo.off");
  constexpr int kPoses = 300;

  std::printf("## Pose → frame latency, Armadillo 26k, %d poses closed loop\n\n", kPoses);
  std::printf("| path | poses | p50 ms | p99 ms | p50 / alone |\n|---|---:|---:|---:|---:|\n");
  double alone_p50 = 0;
  {
    const auto dir = std::filesystem::temp_directory_path() / ("filigree_cluster_bench_" + std::to_string(::getpid()));
    test::ServerProcess alone(FILIGREE_SERVER_BINARY, {"--data-dir", dir.string()});
    Client client(alone.address());
    const SessionHandle s = client.create_session(mesh, "off", {}, "bench");
    drive(client, s, 1, 20);  // warm up
    const auto ms = drive(client, s, 21, 20 + kPoses);
    alone_p50 = percentile(ms, 0.5);
    latency_row("one server, no Redis", ms, alone_p50);
    alone.terminate();
    std::filesystem::remove_all(dir);
  }
  {
    test::Cluster cluster(FILIGREE_SERVER_BINARY, 1, 3000);
    Client direct(cluster.address(0)), lb(cluster.lb());
    const auto t = Clock::now();
    const SessionHandle s = direct.create_session(mesh, "off", {}, "bench");
    const double build_ms = ms_since(t);
    drive(direct, s, 1, 20);
    latency_row("replica journaling to Redis", drive(direct, s, 21, 20 + kPoses), alone_p50);
    latency_row("through nginx to that replica", drive(lb, s, 21 + kPoses, 20 + 2 * kPoses), alone_p50);
    std::printf("\nJournal per pose: %zu base vertices × 12 bytes = %zu bytes of pose written to Redis.\n",
                s.mesh.base_vertex_count(), s.mesh.base_vertex_count() * 12);

    std::printf("\n## Hierarchy: built by one replica, loaded by another (Armadillo 26k)\n\n");
    test::Cluster two(FILIGREE_SERVER_BINARY, 2, 3000);
    Client first(two.address(0)), second(two.address(1));
    auto t1 = Clock::now();
    const SessionHandle a = first.create_session(mesh, "off", {}, "builder");
    const double built_ms = ms_since(t1);
    t1 = Clock::now();
    const SessionHandle b = second.create_session(mesh, "off", {}, "loader");
    const double loaded_ms = ms_since(t1);
    std::printf("| upload to | cached | create_session ms |\n|---|---|---:|\n");
    std::printf("| replica 1 (builds) | %s | %.0f |\n| replica 2 (loads from Redis) | %s | %.0f |\n", a.cached ? "yes" : "no",
                built_ms, b.cached ? "yes" : "no", loaded_ms);
    std::printf("\nbuild / load from Redis: %.1fx (first upload in the one-replica cluster above: %.0f ms)\n",
                built_ms / loaded_ms, build_ms);
  }

  std::printf("\n## Failover: SIGKILL of the serving replica → first acknowledged frame elsewhere (3 replicas, nginx)\n\n");
  std::printf("| lease ms | runs | median ms | max ms |\n|---:|---:|---:|---:|\n");
  for (int lease : {1500, 3000}) {
    std::vector<double> gaps;
    for (int run = 0; run < 3; ++run) {
      test::Cluster cluster(FILIGREE_SERVER_BINARY, 3, lease);
      Client lb(cluster.lb());
      const SessionHandle s = lb.create_session(mesh, "off", {}, "failover");
      drive(lb, s, 1, 10);
      cluster.kill(cluster.index_of(lb.locate(s.session_id, s.viewer_token).replica_id()));
      const auto t = Clock::now();
      for (std::uint64_t i = 11;; ++i) {
        if (!drive(lb, s, i, i).empty()) break;
        if (ms_since(t) > 60000) {
          std::fprintf(stderr, "the session did not come back within 60 s\n");
          return 1;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));  // client retry backoff
      }
      gaps.push_back(ms_since(t));
    }
    std::printf("| %d | %zu | %.0f | %.0f |\n", lease, gaps.size(), percentile(gaps, 0.5), *std::max_element(gaps.begin(), gaps.end()));
  }
  return 0;
}
