#include "runtime/deformer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "geometry/best_fit_rotation.h"
#include "geometry/cotangent_laplacian.h"
#include "hierarchy/hierarchy.h"
#include "runtime/cut.h"
#include "runtime/direct_recovery.h"
#include "runtime/regions.h"
#include "runtime/rotation_interpolation.h"

namespace filigree {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

}  // namespace

struct Deformer::State {
  CotangentLaplacian laplacian;
  BaseRotations rotations;
  std::vector<std::array<Index, 3>> maps_corners;  // per vertex: base-local corners of its MAPS face
  DirectRecovery recovery;
  AdaptiveCut cut;
  RegionSolver solver;
  std::vector<Vec3> positions;  // the last frame's result (rest before the first)
  std::vector<Eigen::Quaterniond> base_q;

  State(const Hierarchy& h, const DeformerOptions& o)
      : laplacian(cotangent_laplacian(h.original_mesh())), rotations(h.base_mesh(), o.rotation), recovery(h), cut(h, laplacian),
        solver(laplacian, h.laplacian), positions(h.rest_positions) {
    std::vector<Index> base_local(h.vertex_count(), kNone);
    for (Index i = 0; i < h.base_vertices.size(); ++i) base_local[h.base_vertices[i]] = i;
    maps_corners.resize(h.vertex_count());
    for (Index v = 0; v < h.vertex_count(); ++v) {
      const Triangle& t = h.faces[h.base_faces[h.maps_face[v]]];
      maps_corners[v] = {base_local[t[0]], base_local[t[1]], base_local[t[2]]};
    }
    cut.reset(o.threshold);
  }
};

Deformer::Deformer(const Hierarchy& h, const DeformerOptions& options) : h_(h), options_(options) {
  if (std::isnan(options.threshold) || options.threshold < 0.0)
    throw std::invalid_argument("threshold must be ≥ 0 (or ∞)");
  if (options.threads < 1) throw std::invalid_argument("threads must be ≥ 1");
  if (options.local_global_iterations < 0) throw std::invalid_argument("local-global iterations must be ≥ 0");
  s_ = std::make_unique<State>(h, options_);
}

Deformer::~Deformer() = default;

std::size_t Deformer::base_vertex_count() const { return h_.base_vertices.size(); }

const std::vector<Index>& Deformer::region_of_vertex() const { return s_->cut.regions().region_of; }

const CutState& Deformer::cut_state() const { return s_->cut.state(); }

void Deformer::set_threshold(double threshold) {
  if (std::isnan(threshold) || threshold < 0.0) throw std::invalid_argument("threshold must be ≥ 0 (or ∞)");
  options_.threshold = threshold;
  s_->cut.set_threshold(threshold);
}

DeformResult Deformer::deform(const Pose& pose) {
  validate_pose(pose, h_.base_vertices.size());
  const auto start = Clock::now();
  State& s = *s_;
  FrameStats stats;
  stats.threshold = options_.threshold;

  // 1. Move the cut where the last frame deformed acutely (thesis §3.3).
  auto t = Clock::now();
  if (options_.update_cut) {
    const std::size_t nodes = h_.node_count();
    const std::size_t eval = options_.cut_eval_budget ? options_.cut_eval_budget : std::max<std::size_t>(2048, nodes / 32);
    const std::size_t moves = options_.cut_move_budget ? options_.cut_move_budget : std::max<std::size_t>(128, nodes / 256);
    stats.cut_moves = s.cut.update(s.positions, eval, moves);
  }
  stats.cut_update_ms = ms_since(t);

  // 2. Direct recovery of the cut, parents first (thesis eq. 3.10).
  t = Clock::now();
  std::vector<Vec3>& x = s.positions;
  for (Index i = 0; i < h_.base_vertices.size(); ++i) x[h_.base_vertices[i]] = pose.positions[i];
  const CutState& cut = s.cut.state();
  s.recovery.recover(cut, x, options_.threads);
  stats.recover_ms = ms_since(t);

  // 3. Rotations of the base vertices; only regions use them, direct
  // recovery carries its own frames.
  const Regions& regions = s.cut.regions();
  t = Clock::now();
  if (regions.count() > 0) s.rotations.compute(pose.positions, s.base_q, options_.threads);
  stats.rotations_ms = ms_since(t);

  // 4. Regions: Dirichlet solves with rotated differential coordinates.
  t = Clock::now();
  auto interpolated = [&](Index v) {
    const auto& c = s.maps_corners[v];
    return interpolate_rotation({s.base_q[c[0]], s.base_q[c[1]], s.base_q[c[2]]}, h_.maps_bary[v]).toRotationMatrix();
  };
  stats.factorizations = s.solver.solve(regions, x, options_.threads, interpolated);
  for (int it = 0; it < options_.local_global_iterations; ++it) {
    // Local step: the best-fit rotation of each region vertex's 1-ring on the
    // current result; global step: solve again (factorisations are cached).
    auto refit = [&](Index v) {
      Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
      for (Index k = s.laplacian.offsets[v]; k < s.laplacian.offsets[v + 1]; ++k) {
        const Index j = s.laplacian.neighbors[k];
        cov += s.laplacian.weights[k] * (h_.rest_positions[j] - h_.rest_positions[v]) * (x[j] - x[v]).transpose();
      }
      return best_fit_rotation(cov);
    };
    stats.factorizations += s.solver.solve(regions, x, options_.threads, refit);
  }
  stats.regions_ms = ms_since(t);

  stats.cut_nodes = cut.recovered_count();
  stats.cut_vertices = h_.base_vertices.size() + stats.cut_nodes;
  stats.regions = regions.count();
  for (std::size_t r = 0; r < regions.count(); ++r) stats.region_sizes.push_back(regions.size(r));
  std::sort(stats.region_sizes.rbegin(), stats.region_sizes.rend());
  stats.region_vertices = regions.vertices.size();
  stats.performance_estimate = regions.performance_estimate();
  stats.total_ms = ms_since(start);
  return {x, std::move(stats)};
}

}  // namespace filigree
