#include "bench/quality_table.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "bench/runtime_animation.h"
#include "bench/sample_stats.h"
#include "bench/session_mesh.h"
#include "hierarchy/hierarchy.h"
#include "metrics/mesh_metrics.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer.h"
#include "runtime/deformer_model.h"
#include "runtime/procedural_motion.h"

namespace filigree::bench {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

struct Setting {
  const char* label;
  double threshold;
  int iterations;  // local–global
};
constexpr double kInf = DeformerOptions::kInfinity;
constexpr Setting kSettings[] = {
    {"T = 0", 0.0, 0}, {"T = 2e4", 2e4, 0}, {"T = 2e5", 2e5, 0}, {"T = ∞", kInf, 0}, {"T = ∞, 10 it.", kInf, 10},
};
constexpr int kSettingCount = static_cast<int>(std::size(kSettings));
constexpr int kZero = 0, kInfinite = 3, kIterated = 4;  // indices into kSettings
constexpr int kFinite[] = {1, 2};
constexpr Motion kTableMotions[] = {Motion::kTwist, Motion::kBend, Motion::kBump, Motion::kFold, Motion::kTwist360};

struct Cell {
  MeshComparison q;  // to the truth, on the last timed frame
  double ms = 0.0;   // median wall-clock time of deform() over the timed frames
  std::size_t region_vertices = 0;
};

struct Row {
  std::string mesh;
  Motion motion;
  Cell cells[kSettingCount];
};

std::string load_average() {
  std::ifstream in("/proc/loadavg");
  std::string one, five, fifteen;
  if (!(in >> one >> five >> fifteen)) return "unknown";
  return one + ", " + five + ", " + fifteen;
}

// One mesh × motion: every setting plays the same animation on a deformer of
// the mesh's shared model (as the service's sessions share it), the ramp as
// warm-up. The settings take their frames in turn, frame by frame, so that
// on a shared machine whose speed drifts over minutes every setting sees the
// same minutes; each timed frame follows an untimed frame of the previous
// pose on its own deformer (as in the motion tables: its caches are its own,
// as a session's frames follow each other).
Row run_case(const std::string& mesh_name, const Hierarchy& h, const std::shared_ptr<const DeformerModel>& model,
             const TriMesh& mesh, Motion motion, int threads) {
  Row row{mesh_name, motion, {}};
  const MotionField field(h.rest_positions, motion, 1.0);
  std::vector<Pose> poses;
  for (int f = 0; f <= kLastFrame; ++f) poses.push_back(base_pose(h, field.with_phase(phase_of(f))));
  TriMesh truth;
  truth.positions = field.with_phase(phase_of(kLastFrame)).apply(h.rest_positions);
  truth.faces = mesh.faces;
  std::vector<std::unique_ptr<Deformer>> deformers;
  // The callers' buffers, reused frame after frame, as the service does.
  std::vector<std::vector<Vec3>> out(kSettingCount, std::vector<Vec3>(h.vertex_count()));
  for (const Setting& setting : kSettings) {
    DeformerOptions o;
    o.threshold = setting.threshold;
    o.local_global_iterations = setting.iterations;
    o.threads = threads;
    deformers.push_back(std::make_unique<Deformer>(model, o));
  }
  for (int f = 0; f < kRampFrames; ++f)
    for (int k = 0; k < kSettingCount; ++k) deformers[k]->deform(poses[f], out[k]);
  std::vector<std::vector<double>> ms(kSettingCount);
  std::vector<FrameStats> last(kSettingCount);
  for (int f = kRampFrames; f <= kLastFrame; ++f)
    for (int k = 0; k < kSettingCount; ++k) {
      deformers[k]->deform(poses[f - 1], out[k]);
      const auto start = Clock::now();
      last[k] = deformers[k]->deform(poses[f], out[k]);
      ms[k].push_back(ms_since(start));
    }
  for (int k = 0; k < kSettingCount; ++k) {
    TriMesh result;
    result.faces = mesh.faces;
    result.positions = std::move(out[k]);
    row.cells[k] = {compare_meshes(result, truth), median(ms[k]), last[k].region_vertices};
  }
  return row;
}

std::string cell_text(const Cell& c) {
  char out[96];
  std::snprintf(out, sizeof out, "%.3f / %.2f / %.2f° / %.3g", 100.0 * c.q.rms_distance, 100.0 * c.q.max_distance,
                c.q.mean_normal_deviation_deg, c.ms);
  return out;
}

bool is_twist_or_fold(Motion m) { return m == Motion::kTwist || m == Motion::kTwist360 || m == Motion::kFold; }

std::string case_name(const Row& r) { return r.mesh + " " + to_string(r.motion); }

// (a) T = ∞ ≤ T = 0 in RMS on every twist, fold and twist360.
void target_a(const std::vector<Row>& rows) {
  std::vector<std::string> failed;
  int cases = 0;
  for (const Row& r : rows) {
    if (!is_twist_or_fold(r.motion)) continue;
    ++cases;
    const double zero = r.cells[kZero].q.rms_distance, inf = r.cells[kInfinite].q.rms_distance;
    if (!(inf <= zero)) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "%s (%.3f%% against %.3f%%)", case_name(r).c_str(), 100 * inf, 100 * zero);
      failed.push_back(buf);
    }
  }
  std::printf("- (a) T = ∞ ≤ T = 0 in RMS on every twist, fold and twist360: **%s** — %d of %d cases hold.",
              failed.empty() ? "met" : "not met", cases - static_cast<int>(failed.size()), cases);
  if (!failed.empty()) {
    std::printf(" T = ∞ above T = 0:");
    for (std::size_t i = 0; i < failed.size(); ++i) std::printf("%s %s", i ? "," : "", failed[i].c_str());
  }
  std::printf("\n");
}

// (b) some finite T ≤ 0.8× T = 0's RMS on the twists and folds at ≤ 3× its time.
void target_b(const std::vector<Row>& rows) {
  int cases = 0, held = 0;
  int held_by[kSettingCount] = {};
  std::vector<std::string> notes;
  for (const Row& r : rows) {
    if (!is_twist_or_fold(r.motion)) continue;
    ++cases;
    const Cell& zero = r.cells[kZero];
    bool any = false;
    std::string detail;
    for (int k : kFinite) {
      const Cell& c = r.cells[k];
      const double rms_ratio = c.q.rms_distance / zero.q.rms_distance, time_ratio = c.ms / zero.ms;
      const bool ok = rms_ratio <= 0.8 && time_ratio <= 3.0;
      any = any || ok;
      held_by[k] += ok;
      char buf[96];
      std::snprintf(buf, sizeof buf, "%s%s %.2f× RMS at %.1f× time", detail.empty() ? "" : ", ", kSettings[k].label,
                    rms_ratio, time_ratio);
      detail += buf;
    }
    held += any;
    notes.push_back(case_name(r) + (any ? " (held: " : " (") + detail + ")");
  }
  std::printf("- (b) some finite T ≤ 0.8× T = 0's RMS on the twists and folds at ≤ 3× its time: **%s** — %d of %d cases hold",
              held == cases ? "met" : "not met", held, cases);
  for (int k : kFinite) std::printf("; %s alone: %d", kSettings[k].label, held_by[k]);
  std::printf(".\n");
  for (const std::string& n : notes) std::printf("  - %s\n", n.c_str());
}

// (c) no case where 10 local–global iterations raise the max error over none
// (both T = ∞). A rise within 1e-9 of the error is rounding, not a rise.
void target_c(const std::vector<Row>& rows) {
  std::vector<std::string> failed;
  for (const Row& r : rows) {
    const double none = r.cells[kInfinite].q.max_distance, ten = r.cells[kIterated].q.max_distance;
    if (ten > none * (1.0 + 1e-9)) {
      char buf[160];
      std::snprintf(buf, sizeof buf, "%s (%.4f%% against %.4f%%, +%.2g%%)", case_name(r).c_str(), 100 * ten, 100 * none,
                    100 * (ten / none - 1.0));
      failed.push_back(buf);
    }
  }
  std::printf("- (c) no case where 10 iterations raise the max error over 0 iterations (T = ∞): **%s** — %zu of %zu cases raise it "
              "(by more than 1e-9 of it).",
              failed.empty() ? "met" : "not met", failed.size(), rows.size());
  if (!failed.empty()) {
    std::printf(" Raised:");
    for (std::size_t i = 0; i < failed.size(); ++i) std::printf("%s %s", i ? "," : "", failed[i].c_str());
  }
  std::printf("\n");
}

// Each setting's RMS, max and time over T = 0's, case by case: the median and the range.
void relative_summary(const std::vector<Row>& rows) {
  auto stat = [](std::vector<double> v) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%.2f× (%.2f–%.2f×)", median(v), *std::min_element(v.begin(), v.end()),
                  *std::max_element(v.begin(), v.end()));
    return std::string(buf);
  };
  std::printf("\n### each setting against T = 0 (median over the %zu cases, and the range)\n\n"
              "| setting | RMS / T = 0 | RMS / T = 0 on twists and folds | max / T = 0 | time / T = 0 | time per frame, ms (range) |\n"
              "|---|---:|---:|---:|---:|---:|\n",
              rows.size());
  for (int k = 0; k < kSettingCount; ++k) {
    std::vector<double> rms, rms_tf, max, time, ms;
    for (const Row& r : rows) {
      const Cell &c = r.cells[k], &zero = r.cells[kZero];
      rms.push_back(c.q.rms_distance / zero.q.rms_distance);
      if (is_twist_or_fold(r.motion)) rms_tf.push_back(c.q.rms_distance / zero.q.rms_distance);
      max.push_back(c.q.max_distance / zero.q.max_distance);
      time.push_back(c.ms / zero.ms);
      ms.push_back(c.ms);
    }
    std::printf("| %s | %s | %s | %s | %s | %.3g–%.3g |\n", kSettings[k].label, stat(rms).c_str(), stat(rms_tf).c_str(),
                stat(max).c_str(), stat(time).c_str(), *std::min_element(ms.begin(), ms.end()),
                *std::max_element(ms.begin(), ms.end()));
  }
}

}  // namespace

void print_quality_table(const std::vector<TableMesh>& meshes, int threads) {
  const auto start = Clock::now();
  const std::string load_before = load_average();
  std::printf("# Filigree runtime quality table (%d threads)\n\n", threads);
  std::printf("| mesh | kind | vertices | base vertices | preprocessing s |\n|---|---|---:|---:|---:|\n");
  std::vector<Row> rows;
  std::vector<std::string> skipped;
  for (const TableMesh& m : meshes) {
    if (!std::filesystem::exists(m.path)) {
      skipped.push_back(m.name + " (" + m.path + " not found)");
      continue;
    }
    const TriMesh mesh = load_clean(m.path);
    PreprocessOptions pre;
    pre.threads = threads;
    const auto t0 = Clock::now();
    const auto h = std::make_shared<const Hierarchy>(preprocess(mesh, pre));
    std::printf("| %s | %s | %zu | %zu | %.1f |\n", m.name.c_str(), m.kind.c_str(), h->vertex_count(), h->base_vertices.size(),
                ms_since(t0) / 1000.0);
    std::fflush(stdout);
    const std::shared_ptr<const DeformerModel> model = DeformerModel::create(h);
    for (Motion motion : kTableMotions) {
      std::fprintf(stderr, "%s %s…\n", m.name.c_str(), to_string(motion));
      rows.push_back(run_case(m.name, *h, model, mesh, motion, threads));
    }
  }
  for (const std::string& s : skipped) std::printf("\nSkipped: %s.\n", s.c_str());
  if (rows.empty()) return;

  std::printf("\nEach cell: RMS / max distance to the truth (%% of the bbox diagonal) / mean normal deviation / time per frame "
              "(ms, the median of %d frames after %d of warm-up; the settings take their frames in turn). The truth is the analytic motion on every vertex, at "
              "full strength (phase %g), the base vertices posed by the same map. \"10 it.\": 10 local–global iterations.\n\n",
              kTimedFrames, kRampFrames, phase_of(kLastFrame));
  std::printf("| mesh | motion |");
  for (const Setting& s : kSettings) std::printf(" %s |", s.label);
  std::printf("\n|---|---|");
  for (int k = 0; k < kSettingCount; ++k) std::printf("---:|");
  std::printf("\n");
  for (const Row& r : rows) {
    std::printf("| %s | %s |", r.mesh.c_str(), to_string(r.motion));
    for (const Cell& c : r.cells) std::printf(" %s |", cell_text(c).c_str());
    std::printf("\n");
  }

  std::printf("\n### targets, from the table above\n\n");
  target_a(rows);
  target_b(rows);
  target_c(rows);
  relative_summary(rows);
  std::printf("\nRun time %.0f s; load average (1, 5, 15 min) %s before, %s after.\n", ms_since(start) / 1000.0,
              load_before.c_str(), load_average().c_str());
}

}  // namespace filigree::bench
