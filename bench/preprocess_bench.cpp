// Preprocessing benchmark: time and peak memory of building the hierarchy for
// meshes of ~10k to ≥2M vertices on one thread and on every core, and how
// much faster the file loads than it builds. Targets: the 1.25M mesh in
// ≤ 12 s with ≤ 600 MiB peak on this 2-core machine, two threads ≥ 1.7× one.
//
// Meshes: the shipped Armadillo (26k) and its subdivisions (104k, 1.25M), plus
// the real meshes in ../shared/data when present (camel 9.8k, dragon 435k,
// the horse subdivided to 2.33M).
// Usage: filigree_bench_preprocess [--threads N] (default: 1, then every core)

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/subdivide.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "preprocess/preprocess.h"
#include "util/memory_usage.h"

namespace filigree::bench {
namespace {

struct MeshCase {
  std::string name;
  std::function<TriMesh()> make;
};

struct Row {
  std::string name;
  int threads = 1;
  std::size_t vertices = 0, base = 0, nodes = 0, depth = 0;
  double seconds = 0.0, peak_mib = 0.0, file_mib = 0.0, load_ms = 0.0;
};
std::vector<Row> rows;

TriMesh load_clean(const std::string& path) {
  RepairReport report;
  return repair_mesh(read_mesh(path), {}, &report);
}

void run_case(benchmark::State& state, const MeshCase& c, int threads) {
  for (auto _ : state) {
    state.PauseTiming();
    const TriMesh mesh = c.make();
    reset_peak_memory();
    PreprocessOptions options;
    options.threads = threads;
    state.ResumeTiming();
    const auto start = std::chrono::steady_clock::now();
    const Hierarchy h = preprocess(mesh, options);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    state.PauseTiming();
    const double peak = static_cast<double>(peak_memory_bytes()) / (1024.0 * 1024.0);

    const auto file = std::filesystem::temp_directory_path() / ("filigree_bench_" + std::to_string(::getpid()) + ".fgh");
    save_hierarchy(h, file);
    const auto load_start = std::chrono::steady_clock::now();
    const Hierarchy loaded = load_hierarchy(file);
    const double load_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - load_start).count();
    const double file_mib = static_cast<double>(std::filesystem::file_size(file)) / (1024.0 * 1024.0);
    std::filesystem::remove(file);
    benchmark::DoNotOptimize(loaded.node_count());

    state.counters["vertices"] = static_cast<double>(mesh.vertex_count());
    state.counters["base"] = static_cast<double>(h.base_vertices.size());
    state.counters["peak_MiB"] = peak;
    state.counters["file_MiB"] = file_mib;
    state.counters["load_ms"] = load_ms;
    rows.push_back({c.name, threads, mesh.vertex_count(), h.base_vertices.size(), h.node_count(), h.depth(), seconds, peak,
                    file_mib, load_ms});
    state.ResumeTiming();
  }
}

}  // namespace
}  // namespace filigree::bench

int main(int argc, char** argv) {
  using namespace filigree;
  using namespace filigree::bench;
  const std::string shared = FILIGREE_SHARED_DATA_DIR, repo = FILIGREE_REPO_DATA_DIR;
  std::vector<MeshCase> cases;
  if (std::filesystem::exists(shared + "/camel.off"))
    cases.push_back({"camel (real, 9.8k)", [=] { return load_clean(shared + "/camel.off"); }});
  cases.push_back({"armadillo (real, 26k)", [=] { return load_clean(repo + "/armadillo.off"); }});
  cases.push_back({"armadillo Loop x1 (104k)", [=] { return subdivide(load_clean(repo + "/armadillo.off"), 1, 0); }});
  if (std::filesystem::exists(shared + "/dragon.ply"))
    cases.push_back({"dragon (real, 435k)", [=] { return load_clean(shared + "/dragon.ply"); }});
  cases.push_back({"armadillo Loop x2 + sqrt3 (1.25M)", [=] { return subdivide(load_clean(repo + "/armadillo.off"), 2, 1); }});
  if (std::filesystem::exists(shared + "/horse.ply"))
    cases.push_back({"horse Loop x2 + sqrt3 (2.33M)", [=] { return subdivide(load_clean(shared + "/horse.ply"), 2, 1); }});

  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::vector<int> thread_counts = {1, cores};
  for (int i = 1; i + 1 < argc; ++i)
    if (std::string(argv[i]) == "--threads") thread_counts = {std::max(1, std::atoi(argv[i + 1]))};
  if (thread_counts.size() == 2 && cores == 1) thread_counts.pop_back();
  for (const MeshCase& c : cases)
    for (int threads : thread_counts)
      benchmark::RegisterBenchmark(("preprocess/" + c.name + "/threads:" + std::to_string(threads)).c_str(),
                                   [c, threads](benchmark::State& s) { run_case(s, c, threads); })
          ->Iterations(1)
          ->Unit(benchmark::kSecond)
          ->UseRealTime();
  // Our --threads is not Google Benchmark's: take it out before it parses.
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::string(argv[i]) == "--threads" && i + 1 < argc) {
      ++i;
      continue;
    }
    args.push_back(argv[i]);
  }
  argc = static_cast<int>(args.size());
  argv = args.data();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();

  std::printf("\n| mesh | threads | vertices | base | nodes | depth | preprocess (s) | vs 1 thread | peak memory (MiB) | file (MiB) | load (ms) | build / load |\n");
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const Row& r : rows) {
    double one = 0.0;
    for (const Row& o : rows)
      if (o.name == r.name && o.threads == 1) one = o.seconds;
    std::printf("| %s | %d | %zu | %zu | %zu | %zu | %.2f | %s | %.0f | %.1f | %.1f | %.0fx |\n", r.name.c_str(), r.threads,
                r.vertices, r.base, r.nodes, r.depth, r.seconds,
                one > 0.0 ? (std::to_string(one / r.seconds).substr(0, 4) + "x").c_str() : "-", r.peak_mib, r.file_mib,
                r.load_ms, 1000.0 * r.seconds / r.load_ms);
  }
  std::printf("\nTargets: the 1.25M mesh in <= 12 s with <= 600 MiB peak, %d threads >= 1.7x one (%d hardware threads here).\n",
              cores, cores);
  return 0;
}
