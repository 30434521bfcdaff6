// Runtime benchmark (issue 3): one markdown table per mesh × motion with, for
// each threshold T, per-stage and total frame time, the prefactored
// whole-mesh solve on the same pose, and the distance to the T = ∞ result.
//
// Every T runs the same animation: the motion ramps in over 8 frames, then
// 12 timed frames oscillate around full strength, so the cut update works as
// it does in use. Quality is measured on the last timed frame.
//
// Usage: filigree_bench_runtime [--mesh camel|armadillo|dragon|large] [--quick] [--threads N]
//   --quick: only the shipped Armadillo (for a fast look).

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "bench/subdivide.h"
#include "hierarchy/hierarchy.h"
#include "metrics/mesh_metrics.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer.h"
#include "runtime/procedural_motion.h"

namespace filigree::bench {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

constexpr int kRampFrames = 8;
constexpr int kTimedFrames = 12;

double phase_of(int frame) {
  if (frame < kRampFrames) return static_cast<double>(frame + 1) / kRampFrames;
  return 0.9 + 0.1 * std::cos(0.7 * (frame - kRampFrames));
}

TriMesh load_clean(const std::string& path) {
  RepairReport report;
  return repair_mesh(read_mesh(path), {}, &report);
}

struct Timing {
  double rotations = 0, cut = 0, recover = 0, regions = 0, total = 0;
  std::size_t regions_count = 0, region_vertices = 0, factorizations = 0;
};

// Mean relative change of edge lengths: how much of the rest shape's local
// detail a result keeps (0 for a rigid motion of the rest mesh).
double edge_distortion(const TriMesh& mesh, const std::vector<Vec3>& x) {
  double sum = 0.0;
  std::size_t count = 0;
  for (const Triangle& f : mesh.faces)
    for (int c = 0; c < 3; ++c) {
      const Index a = f[c], b = f[(c + 1) % 3];
      const double rest = (mesh.positions[a] - mesh.positions[b]).norm();
      if (rest > 0.0) sum += std::abs((x[a] - x[b]).norm() - rest) / rest, ++count;
    }
  return count ? sum / static_cast<double>(count) : 0.0;
}

// The two rotation methods (DESIGN §2.2.1) on the full motion, whole-mesh
// optimisation and direct recovery.
void compare_rotation_methods(const Hierarchy& h, const TriMesh& mesh, const std::vector<Vec3>& base_rest, int threads) {
  std::printf("\n### rotation methods (full-strength pose; edge distortion = mean relative edge length change)\n\n");
  std::printf("| motion | method | rotations ms | edge distortion T=∞ | edge distortion T=0 |\n|---|---|---:|---:|---:|\n");
  for (Motion motion : {Motion::kBend, Motion::kTwist, Motion::kBump}) {
    const Pose pose = procedural_pose(base_rest, motion, 1.0);
    for (RotationMethod method : {RotationMethod::kBestFit, RotationMethod::kLocalFrame}) {
      double distortion[2] = {0, 0}, rotations_ms = 0;
      for (int i = 0; i < 2; ++i) {
        DeformerOptions o;
        o.threshold = i == 0 ? DeformerOptions::kInfinity : 0.0;
        o.rotation = method;
        o.threads = threads;
        Deformer d(h, o);
        const DeformResult r = d.deform(pose);
        distortion[i] = edge_distortion(mesh, r.positions);
        if (i == 0) rotations_ms = r.stats.rotations_ms;  // T = 0 needs no rotations
      }
      std::printf("| %s | %s | %.2f | %.3f%% | %.3f%% |\n", to_string(motion), to_string(method), rotations_ms,
                  100 * distortion[0], 100 * distortion[1]);
    }
  }
}

void run_mesh(const std::string& name, const TriMesh& mesh, int threads) {
  PreprocessOptions pre;
  pre.threads = threads;
  const auto t0 = Clock::now();
  const Hierarchy h = preprocess(mesh, pre);
  std::printf("\n## %s: %zu vertices, base %zu (preprocessed in %.1f s)\n", name.c_str(), h.vertex_count(),
              h.base_vertices.size(), ms_since(t0) / 1000.0);
  const std::vector<Vec3> base_rest = h.base_mesh().positions;
  compare_rotation_methods(h, mesh, base_rest, threads);

  for (Motion motion : {Motion::kBend, Motion::kTwist, Motion::kBump}) {
    auto pose_at = [&](int frame) { return procedural_pose(base_rest, motion, phase_of(frame)); };
    // The reference: whole-mesh optimisation, factorised on the first frame.
    DeformerOptions ref_options;
    ref_options.threshold = DeformerOptions::kInfinity;
    ref_options.threads = threads;
    Deformer reference(h, ref_options);
    auto t = Clock::now();
    reference.deform(pose_at(0));
    const double factor_ms = ms_since(t);
    double whole_ms = 0.0;
    std::vector<Vec3> best;
    for (int f = kRampFrames; f < kRampFrames + kTimedFrames; ++f) {
      t = Clock::now();
      best = reference.deform(pose_at(f)).positions;
      whole_ms += ms_since(t) / kTimedFrames;
    }

    std::printf("\n### %s, %s (whole-mesh solve %.1f ms per frame prefactored; factorisation + first solve %.0f ms)\n\n",
                name.c_str(), to_string(motion), whole_ms, factor_ms);
    std::printf("| T | rotations ms | cut update ms | recover ms | regions ms | total ms | vs whole | regions | optimised vertices | RMS dist | max dist | normal dev (deg) |\n");
    std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    const std::vector<double> thresholds = {0.0, 2e4, 2e5, 2e6, DeformerOptions::kInfinity};
    for (double threshold : thresholds) {
      DeformerOptions o;
      o.threshold = threshold;
      o.threads = threads;
      Deformer d(h, o);
      for (int f = 0; f < kRampFrames; ++f) d.deform(pose_at(f));
      Timing tm;
      DeformResult last;
      for (int f = kRampFrames; f < kRampFrames + kTimedFrames; ++f) {
        last = d.deform(pose_at(f));
        const FrameStats& s = last.stats;
        tm.rotations += s.rotations_ms / kTimedFrames;
        tm.cut += s.cut_update_ms / kTimedFrames;
        tm.recover += s.recover_ms / kTimedFrames;
        tm.regions += s.regions_ms / kTimedFrames;
        tm.total += s.total_ms / kTimedFrames;
      }
      TriMesh a, b;
      a.positions = last.positions;
      b.positions = best;
      b.faces = mesh.faces;
      const MeshComparison q = compare_meshes(a, b);
      std::string label = threshold == DeformerOptions::kInfinity ? "∞" : std::to_string(static_cast<long>(threshold));
      if (threshold == DeformerOptions::kDefaultThreshold) label += " (default)";
      std::printf("| %s | %.2f | %.2f | %.2f | %.2f | %.2f | %.1fx | %zu | %zu | %.3f%% | %.3f%% | %.2f |\n", label.c_str(),
                  tm.rotations, tm.cut, tm.recover, tm.regions, tm.total, whole_ms / tm.total, last.stats.regions,
                  last.stats.region_vertices, 100.0 * q.rms_distance, 100.0 * q.max_distance, q.mean_normal_deviation_deg);
      std::fflush(stdout);
    }
  }
}

}  // namespace
}  // namespace filigree::bench

int main(int argc, char** argv) {
  using namespace filigree;
  std::string only;  // camel, armadillo, dragon or large; empty: all
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) only = "armadillo";
    if (!std::strcmp(argv[i], "--mesh") && i + 1 < argc) only = argv[++i];
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
  }
  const std::string shared = FILIGREE_SHARED_DATA_DIR, repo = FILIGREE_REPO_DATA_DIR;
  auto wanted = [&](const char* name) { return only.empty() || only == name; };
  std::printf("# Filigree runtime benchmark (%d threads; distances as %% of the bbox diagonal, to the T = ∞ result)\n", threads);
  if (wanted("camel") && std::filesystem::exists(shared + "/camel.off"))
    bench::run_mesh("camel (real)", bench::load_clean(shared + "/camel.off"), threads);
  if (wanted("armadillo")) bench::run_mesh("armadillo (real)", bench::load_clean(repo + "/armadillo.off"), threads);
  if (wanted("dragon") && std::filesystem::exists(shared + "/dragon.ply"))
    bench::run_mesh("dragon (real)", bench::load_clean(shared + "/dragon.ply"), threads);
  if (wanted("large"))
    bench::run_mesh("armadillo Loop x2 + sqrt3", bench::subdivide(bench::load_clean(repo + "/armadillo.off"), 2, 1), threads);
  return 0;
}
