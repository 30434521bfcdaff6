// Runtime benchmark (issues 3 and 10): one markdown table per mesh × motion with,
// for each threshold T, per-stage and total frame time, the prefactored
// whole-mesh solve on the same pose, and the quality of the result twice:
// against the *truth* (the analytic motion applied to every vertex, DESIGN §2.3)
// and against the T = ∞ (whole-mesh optimisation) result, which is a reference
// point, not the best answer.
//
// A motion is a MotionField built from the whole rest mesh: it poses the base
// vertices (original vertices, so the pose is exactly the truth on them) and
// gives the truth on every vertex. Every T runs the same animation: the motion
// ramps in over 8 frames, then 12 timed frames go once round an oscillation
// that ends at full strength, so the cut update works as it does in use.
// Times are medians of the timed frames (per stage, and of the total): on a
// shared machine one descheduled frame would move a mean by 10–40%. Each
// timed frame follows the whole-mesh solve of the same pose, and "vs whole"
// divides the medians of those pairs.
// Quality is measured on the last timed frame, at phase 1.
//
// Usage: filigree_bench_runtime [--mesh camel|armadillo|dragon|large] [--quick] [--bound N] [--kernels N] [--threads N] [--table]
//   --quick: only the shipped Armadillo (for a fast look).
//   --bound N: only the streaming-bound table, N times over (its spread on
//   a shared machine).
//   --kernels N: only the kernel's compiled copies against each other, N
//   frames each.
//   --table: only one quality table to choose T by (bench/quality_table.h):
//   real meshes of several kinds × motions × T, and the runtime's quality
//   targets computed from it; with --mesh, that mesh alone.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <memory>
#include <numbers>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "bench/quality_table.h"
#include "bench/runtime_animation.h"
#include "bench/sample_stats.h"
#include "bench/session_mesh.h"
#include "bench/streaming_bound.h"
#include "bench/subdivide.h"
#include "hierarchy/hierarchy.h"
#include "metrics/mesh_metrics.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer.h"
#include "runtime/deformer_model.h"
#include "runtime/direct_recovery.h"
#include "runtime/procedural_motion.h"

namespace filigree::bench {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

constexpr Motion kMotions[] = {Motion::kBend, Motion::kTwist, Motion::kBump, Motion::kFold};

// Per-frame stage times of the timed frames.
struct Timing {
  std::vector<double> rotations, cut, recover, regions, total;
  void add(const FrameStats& s) {
    rotations.push_back(s.rotations_ms), cut.push_back(s.cut_update_ms), recover.push_back(s.recover_ms);
    regions.push_back(s.regions_ms), total.push_back(s.total_ms);
  }
};

// Direct recovery against its memory bound (issue 10 items 1–2): the bytes a
// T = 0 frame must move, and a plain streaming copy of as many bytes on as
// many threads, timed here in the same run, interleaved frame by frame (on a
// shared machine whose speed drifts, both then see the same minutes; each
// timed copy follows an untimed one, so it is the plain copy, not the
// write-back of the frame's output). The ratio is of the two medians; the
// fastest copy is printed too.
void recovery_bound(const Hierarchy& h, int threads) {
  DeformerOptions o;
  o.threads = threads;
  const auto start = Clock::now();
  Deformer d(DeformerModel::create(std::shared_ptr<const Hierarchy>(&h, [](const Hierarchy*) {})), o);
  const double build_ms = ms_since(start);
  const MotionField field(h.rest_positions, Motion::kBend, 1.0);
  std::vector<Pose> poses;
  for (int f = 0; f < 5; ++f) poses.push_back(base_pose(h, field.with_phase(0.6 + 0.1 * f)));
  std::vector<Vec3> out(h.vertex_count());  // the caller's buffer, reused: the steady state
  const DirectRecovery& r = d.model().recovery();
  const std::size_t bytes = r.bytes_per_frame();
  StreamingCopy copy(bytes);
  std::vector<double> recover, copied;
  for (int f = 0; f < 25; ++f) {
    recover.push_back(d.deform(poses[f % poses.size()], out).recover_ms);
    // An untimed copy first: it writes back what the frame left dirty in the
    // caches, which the timed copy would otherwise pay for.
    (void)copy.run_ms(threads);
    copied.push_back(copy.run_ms(threads));
  }
  const double recover_ms = median(recover), copy_ms = median(copied);
  const double fastest_copy_ms = *std::min_element(copied.begin(), copied.end());
  const double n = static_cast<double>(h.vertex_count());
  std::printf("\n### direct recovery (T = 0) against the streaming bound\n\nKernel: %s (compiled copies this processor runs: ",
              std::string(r.kernel()).c_str());
  const std::vector<std::string_view> kernels = DirectRecovery::kernels();
  for (std::size_t i = 0; i < kernels.size(); ++i) std::printf("%s%s", std::string(kernels[i]).c_str(), i + 1 < kernels.size() ? ", " : ")\n\n");
  std::printf("| vertices | partitions | layout build ms | recover ms (median of 25) | ns/vertex | poses/s | bytes/frame (MB) "
              "| streaming copy ms (median of 25, interleaved) | bound ns/vertex | recover / bound | fastest copy ms | recover / fastest copy |\n"
              "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  std::printf("| %zu | %zu | %.0f | %.2f | %.1f | %.0f | %.1f | %.2f | %.1f | %.2f | %.2f | %.2f |\n", h.vertex_count(), r.partitions(),
              build_ms, recover_ms, 1e6 * recover_ms / n, 1000.0 / recover_ms, static_cast<double>(bytes) / 1e6, copy_ms,
              1e6 * copy_ms / n, recover_ms / copy_ms, fastest_copy_ms, recover_ms / fastest_copy_ms);
  std::printf("\nMemory: the shared model's recovery layout %.0f B/vertex; a deformer's own state %.0f B/vertex.\n",
              static_cast<double>(d.model().memory_bytes()) / n, static_cast<double>(d.memory_bytes()) / n);
}

// The kernel's compiled copies against each other (issue 10 item 1):
// one layout per copy, frames interleaved copy by copy, so that every copy
// sees the same minutes of a machine whose speed drifts.
void compare_kernels(const Hierarchy& h, int threads, int rounds) {
  const std::vector<std::string_view> names = DirectRecovery::kernels();
  std::vector<std::unique_ptr<DirectRecovery>> copies;
  for (std::string_view name : names) copies.push_back(std::make_unique<DirectRecovery>(h, 0, name));
  const MotionField field(h.rest_positions, Motion::kBend, 1.0);
  std::vector<std::vector<Vec3>> bases;
  for (int f = 0; f < 5; ++f) bases.push_back(base_pose(h, field.with_phase(0.6 + 0.1 * f)).positions);
  RecoveryWorkspace ws;
  std::vector<Vec3> out(h.vertex_count());
  std::vector<std::vector<double>> ms(copies.size());
  // Each round starts one copy later: a frame runs in the caches the one
  // before it left, and every copy follows every other equally often.
  for (int round = 0; round < rounds; ++round)
    for (std::size_t j = 0; j < copies.size(); ++j) {
      const std::size_t k = (j + static_cast<std::size_t>(round)) % copies.size();
      const auto start = Clock::now();
      copies[k]->recover(bases[round % bases.size()], ws, out, threads);
      ms[k].push_back(ms_since(start));
    }
  std::printf("\n### the kernel's compiled copies, %d frames each, interleaved\n\n| kernel | recover ms (median) | ns/vertex | against %s |\n"
              "|---|---:|---:|---:|\n",
              rounds, std::string(names.back()).c_str());
  const double last = median(ms.back());
  for (std::size_t k = 0; k < copies.size(); ++k)
    std::printf("| %s | %.2f | %.1f | %.2f |\n", std::string(names[k]).c_str(), median(ms[k]),
                1e6 * median(ms[k]) / static_cast<double>(h.vertex_count()), median(ms[k]) / last);
}

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
void compare_rotation_methods(const Hierarchy& h, const TriMesh& mesh, int threads) {
  std::printf("\n### rotation methods (full-strength pose; edge distortion = mean relative edge length change; "
              "the truth's own is the motion's: none of them is an isometry)\n\n");
  std::printf("| motion | method | rotations ms | edge distortion T=∞ | edge distortion T=0 | edge distortion of the truth |\n"
              "|---|---|---:|---:|---:|---:|\n");
  for (Motion motion : kMotions) {
    const MotionField field(h.rest_positions, motion, 1.0);
    const Pose pose = base_pose(h, field);
    const double truth_distortion = edge_distortion(mesh, field.apply(h.rest_positions));
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
      std::printf("| %s | %s | %.2f | %.3f%% | %.3f%% | %.3f%% |\n", to_string(motion), to_string(method), rotations_ms,
                  100 * distortion[0], 100 * distortion[1], 100 * truth_distortion);
    }
  }
}

// A quality column group: RMS and max distance (% of the reference's bbox
// diagonal) and mean normal deviation (degrees).
std::string quality(const MeshComparison& q) {
  char out[128];
  std::snprintf(out, sizeof out, "%.3f%% | %.3f%% | %.2f", 100.0 * q.rms_distance, 100.0 * q.max_distance,
                q.mean_normal_deviation_deg);
  return out;
}

void run_mesh(const std::string& name, const TriMesh& mesh, int threads, int bound_only, int kernel_rounds) {
  PreprocessOptions pre;
  pre.threads = threads;
  const auto t0 = Clock::now();
  const Hierarchy h = preprocess(mesh, pre);
  std::printf("\n## %s: %zu vertices, base %zu (preprocessed in %.1f s)\n", name.c_str(), h.vertex_count(),
              h.base_vertices.size(), ms_since(t0) / 1000.0);
  if (h.rest_positions.size() != mesh.positions.size()) throw std::logic_error("the hierarchy is not of this mesh");

  if (kernel_rounds > 0) {
    compare_kernels(h, threads, kernel_rounds);
    return;
  }
  if (bound_only > 0) {
    for (int i = 0; i < bound_only; ++i) recovery_bound(h, threads);
    return;
  }
  recovery_bound(h, threads);

  compare_rotation_methods(h, mesh, threads);

  const double quality_phase = phase_of(kLastFrame);
  for (Motion motion : kMotions) {
    // The field's frame (bbox, axes, bump centre) comes from the whole rest mesh.
    const MotionField field(h.rest_positions, motion, 1.0);
    auto pose_at = [&](int frame) { return base_pose(h, field.with_phase(phase_of(frame))); };
    TriMesh truth;
    truth.positions = field.with_phase(quality_phase).apply(h.rest_positions);
    truth.faces = mesh.faces;

    // The reference: whole-mesh optimisation, factorised on the first frame.
    DeformerOptions ref_options;
    ref_options.threshold = DeformerOptions::kInfinity;
    ref_options.threads = threads;
    Deformer reference(h, ref_options);
    const Pose first = pose_at(0);
    auto t = Clock::now();
    reference.deform(first);
    const double factor_ms = ms_since(t);
    std::vector<double> whole_frames;
    TriMesh best;
    best.faces = mesh.faces;
    // Every deformer below writes into a buffer of the caller's, reused frame
    // after frame, as the service does: a fresh 10–30 MB vector per frame
    // would time the kernel's page faults, not the runtime.
    best.positions.resize(h.vertex_count());
    for (int f = kRampFrames; f <= kLastFrame; ++f) {
      const Pose pose = pose_at(f);  // made outside the clock, as the Deformer's own stage times are
      t = Clock::now();
      reference.deform(pose, best.positions);
      whole_frames.push_back(ms_since(t));
    }
    const double whole_ms = median(whole_frames);

    std::printf("\n### %s, %s (quality at phase %g; whole-mesh solve %.1f ms per frame prefactored (median); factorisation + first solve %.0f ms)\n\n",
                name.c_str(), to_string(motion), quality_phase, whole_ms, factor_ms);
    std::printf("| T | first frame ms | rotations ms | cut update ms | recover ms | regions ms | total ms | whole-mesh ms, same frames | vs whole | regions "
                "| optimised vertices | RMS to truth | max to truth | normal dev to truth (deg) | RMS to ∞ | max to ∞ | normal dev to ∞ (deg) |\n");
    std::printf("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    std::vector<Vec3> paired(h.vertex_count());  // the whole-mesh solve's output, timed beside each row
    const std::vector<double> thresholds = {0.0, 2e4, 2e5, 2e6, DeformerOptions::kInfinity};
    for (double threshold : thresholds) {
      DeformerOptions o;
      o.threshold = threshold;
      o.threads = threads;
      TriMesh result;
      result.positions.resize(h.vertex_count());
      // The first frame with its set-up: the deformer's shared model (the
      // recovery layout; for T > 0 the node graph, Laplacian and cut) built
      // from the hierarchy, as for the first session of a mesh.
      const Pose first_pose = pose_at(0);
      const auto first_start = Clock::now();
      Deformer d(h, o);
      d.deform(first_pose, result.positions);
      const double first_ms = ms_since(first_start);
      for (int f = 1; f < kRampFrames; ++f) d.deform(pose_at(f), result.positions);
      // Each timed frame close to the whole-mesh solve of the same pose: on a
      // shared machine whose speed drifts, the ratio compares like with like.
      // Between them an untimed frame of the previous pose, as a session's
      // frames follow each other: at 1.25M a frame right after a 0.4–1 s
      // solve ran 2–15× slower than one after another frame (this VM).
      Timing tm;
      FrameStats s;
      std::vector<double> whole_here;
      Pose previous = pose_at(kRampFrames - 1);
      for (int f = kRampFrames; f <= kLastFrame; ++f) {
        Pose pose = pose_at(f);
        const auto whole_start = Clock::now();
        reference.deform(pose, paired);
        whole_here.push_back(ms_since(whole_start));
        d.deform(previous, result.positions);
        s = d.deform(pose, result.positions);
        tm.add(s);
        previous = std::move(pose);
      }
      const std::string to_truth = quality(compare_meshes(result, truth)), to_best = quality(compare_meshes(result, best));
      std::string label = threshold == DeformerOptions::kInfinity ? "∞" : std::to_string(static_cast<long>(threshold));
      if (threshold == DeformerOptions::kDefaultThreshold) label += " (default)";
      const double total = median(tm.total);
      const double whole_paired = median(whole_here);
      std::printf("| %s | %.0f | %.2f | %.2f | %.2f | %.2f | %.2f | %.1f | %.1fx | %zu | %zu | %s | %s |\n", label.c_str(), first_ms,
                  median(tm.rotations), median(tm.cut), median(tm.recover), median(tm.regions), total, whole_paired, whole_paired / total,
                  s.regions, s.region_vertices, to_truth.c_str(), to_best.c_str());
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
  int bound_only = 0, kernel_rounds = 0;
  bool table = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--quick")) only = "armadillo";
    if (!std::strcmp(argv[i], "--mesh") && i + 1 < argc) only = argv[++i];
    if (!std::strcmp(argv[i], "--threads") && i + 1 < argc) threads = std::atoi(argv[++i]);
    if (!std::strcmp(argv[i], "--bound") && i + 1 < argc) bound_only = std::max(1, std::atoi(argv[++i]));
    if (!std::strcmp(argv[i], "--kernels") && i + 1 < argc) kernel_rounds = std::max(1, std::atoi(argv[++i]));
    if (!std::strcmp(argv[i], "--table")) table = true;
  }
  const std::string shared = FILIGREE_SHARED_DATA_DIR, repo = FILIGREE_REPO_DATA_DIR;
  auto wanted = [&](const char* name) { return only.empty() || only == name; };
  if (table) {
    const std::vector<bench::TableMesh> all = {
        {"armadillo", "scan, decimated; shipped", repo + "/armadillo.off"},
        {"camel", "thin limbs", shared + "/camel.off"},
        {"horse", "scan (Cyberware), faces inward", shared + "/horse.ply"},
        {"bunny", "scan, remeshed", shared + "/bunny.off"},
        {"elephant", "genus 3, coarse", shared + "/elephant.off"},
        {"lion_head", "open (one boundary loop)", shared + "/lion_head.off"},
    };
    std::vector<bench::TableMesh> meshes;
    for (const bench::TableMesh& m : all)
      if (wanted(m.name.c_str())) meshes.push_back(m);
    bench::print_quality_table(meshes, threads);
    return 0;
  }
  std::printf("# Filigree runtime benchmark (%d threads)\n\n"
              "Quality of each T on the last timed frame: RMS and max vertex distance as %% of the bbox diagonal and\n"
              "mean normal deviation, *to truth* (the analytic motion applied to every vertex; the base vertices are\n"
              "posed by the same map) and *to ∞* (the whole-mesh optimisation result of the same pose).\n",
              threads);
  if (wanted("camel") && std::filesystem::exists(shared + "/camel.off"))
    bench::run_mesh("camel (real)", bench::load_clean(shared + "/camel.off"), threads, bound_only, kernel_rounds);
  if (wanted("armadillo")) bench::run_mesh("armadillo (real)", bench::load_clean(repo + "/armadillo.off"), threads, bound_only, kernel_rounds);
  if (wanted("dragon") && std::filesystem::exists(shared + "/dragon.ply"))
    bench::run_mesh("dragon (real)", bench::load_clean(shared + "/dragon.ply"), threads, bound_only, kernel_rounds);
  if (wanted("large"))
    bench::run_mesh("armadillo Loop x2 + sqrt3",
                    bench::in_session_order(bench::subdivide(bench::load_clean(repo + "/armadillo.off"), 2, 1)), threads, bound_only, kernel_rounds);
  return 0;
}
