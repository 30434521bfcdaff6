#include "runtime/cut.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "geometry/cotangent_laplacian.h"
#include "geometry/triangle_geometry.h"

namespace filigree {
namespace {

// Singular values (Γ ≥ γ) of the affine map taking rest triangle p to q
// (thesis §3.3.1, eq. 3.7).
std::pair<double, double> stretch(const Vec3& p0, const Vec3& p1, const Vec3& p2, const Vec3& q0, const Vec3& q1,
                                  const Vec3& q2) {
  const Vec3 e1 = p1 - p0, e2 = p2 - p0;
  const double l1 = e1.norm();
  const Vec3 n = e1.cross(e2);
  if (!(l1 > 0.0) || !(n.norm() > 0.0)) return {1.0, 1.0};
  const Vec3 u = e1 / l1, w = n.normalized().cross(u);
  Eigen::Matrix2d rest;
  rest << l1, e2.dot(u), 0.0, e2.dot(w);
  Eigen::Matrix<double, 3, 2> posed;
  posed.col(0) = q1 - q0;
  posed.col(1) = q2 - q0;
  const Eigen::Matrix<double, 3, 2> j = posed * rest.inverse();
  const Eigen::Matrix2d jtj = j.transpose() * j;
  const double tr = jtj.trace(), det = jtj.determinant();
  const double disc = std::sqrt(std::max(0.25 * tr * tr - det, 0.0));
  return {std::sqrt(std::max(0.5 * tr + disc, 0.0)), std::sqrt(std::max(0.5 * tr - disc, 0.0))};
}

double dihedral(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  // Angle between the normals of (a, b, c) and (b, a, d), which share edge ab.
  const Vec3 n1 = (b - a).cross(c - a), n2 = (a - b).cross(d - b);
  return std::atan2(n1.cross(n2).norm(), n1.dot(n2));
}

// A swap must improve the acuteness handed to optimisation by this factor.
constexpr double kSwapGain = 1.5;
// Weight of the fraction of a node's mesh neighbours that are optimised.
constexpr double kGrowthBonus = 4.0;

}  // namespace

AdaptiveCut::AdaptiveCut(const Hierarchy& h, const CotangentLaplacian& laplacian)
    : h_(h), laplacian_(laplacian), cut_(h), score_(h.node_count(), 0.0), stamp_(h.node_count(), 0) {
  reset(kInfinity);
}

void AdaptiveCut::reset(double threshold) {
  threshold_ = threshold;
  cut_ = CutState(h_);
  if (threshold < kInfinity)
    for (NodeId k : recovery_order(h_)) cut_.recover(k);
  in_cut_.assign(h_.vertex_count(), false);
  for (Index v = 0; v < h_.vertex_count(); ++v) in_cut_[v] = cut_.vertex_present(v);
  recoverable_ = {};
  removable_ = {};
  std::fill(score_.begin(), score_.end(), 0.0);
  for (NodeId k = 0; k < h_.node_count(); ++k) enqueue(k);
  rebuild_regions();
}

void AdaptiveCut::set_threshold(double threshold) {
  const auto special = [](double t) { return t <= 0.0 || t == kInfinity; };
  if (special(threshold) || special(threshold_)) {
    reset(threshold);
  } else {
    threshold_ = threshold;
  }
}

double AdaptiveCut::evaluate(NodeId k, const std::vector<Vec3>& x) const {
  std::span<const FaceId> faces;
  if (cut_.can_recover(k)) {
    faces = h_.created_faces_of(k);
  } else if (cut_.can_remove(k)) {
    faces = h_.removed_faces_of(k);
  } else {
    return -1.0;
  }
  const auto& p = h_.rest_positions;
  double stretch_sum = 0.0, area_sum = 0.0, bend = 0.0, edge_sum = 0.0;
  for (std::size_t i = 0; i < faces.size(); ++i) {
    const Triangle& t = h_.faces[faces[i]];
    const double area = triangle_area(p[t[0]], p[t[1]], p[t[2]]);
    const auto [big, small] = stretch(p[t[0]], p[t[1]], p[t[2]], x[t[0]], x[t[1]], x[t[2]]);
    stretch_sum += area * ((big - 1.0) * (big - 1.0) + (small - 1.0) * (small - 1.0));
    area_sum += area;
    // Normal difference (thesis §3.3.2, eq. 3.8) on edges shared inside the patch.
    for (std::size_t j = i + 1; j < faces.size(); ++j) {
      const Triangle& s = h_.faces[faces[j]];
      for (int c = 0; c < 3; ++c) {
        const Index a = t[c], b = t[(c + 1) % 3];
        for (int e = 0; e < 3; ++e) {
          if (s[e] != b || s[(e + 1) % 3] != a) continue;
          const Index tc = t[(c + 2) % 3], sd = s[(e + 2) % 3];
          const double len = (p[a] - p[b]).norm();
          bend += len * std::abs(dihedral(x[a], x[b], x[tc], x[sd]) - dihedral(p[a], p[b], p[tc], p[sd]));
          edge_sum += len;
        }
      }
    }
  }
  const double acuteness = (area_sum > 0.0 ? stretch_sum / area_sum : 0.0) + (edge_sum > 0.0 ? bend / edge_sum : 0.0);
  // Favour nodes next to optimised vertices, in both queues: un-recovering
  // them grows regions instead of scattering one-vertex regions that the cut
  // pins in place (percolation, DESIGN §2.2.4); recovering isolated ones
  // first removes exactly those useless islands.
  const Index v = h_.node_vertex[k];
  double free_neighbours = 0.0;
  const double degree = static_cast<double>(laplacian_.offsets[v + 1] - laplacian_.offsets[v]);
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) free_neighbours += in_cut_[laplacian_.neighbors[i]] ? 0.0 : 1.0;
  return acuteness * (1.0 + kGrowthBonus * free_neighbours / std::max(degree, 1.0));
}

void AdaptiveCut::enqueue(NodeId k) {
  ++stamp_[k];
  if (cut_.can_recover(k)) recoverable_.push({score_[k], k, stamp_[k]});
  if (cut_.can_remove(k)) removable_.push({score_[k], k, stamp_[k]});
}

void AdaptiveCut::enqueue_neighbours(NodeId k) {
  enqueue(k);
  for (NodeId p : h_.parents_of(k)) enqueue(p);
  for (NodeId c : h_.children_of(k)) enqueue(c);
}

NodeId AdaptiveCut::top_recoverable() {
  while (!recoverable_.empty()) {
    const Entry& e = recoverable_.top();
    if (e.stamp == stamp_[e.node] && cut_.can_recover(e.node)) return e.node;
    recoverable_.pop();
  }
  return kNone;
}

NodeId AdaptiveCut::top_removable() {
  while (!removable_.empty()) {
    const Entry& e = removable_.top();
    if (e.stamp == stamp_[e.node] && cut_.can_remove(e.node)) return e.node;
    removable_.pop();
  }
  return kNone;
}

Index AdaptiveCut::region_root(Index v) {
  Index r = est_region_[v];
  while (uf_parent_[r] != r) r = uf_parent_[r] = uf_parent_[uf_parent_[r]];
  return r;
}

double AdaptiveCut::delta_unrecover(NodeId k) {
  const Index v = h_.node_vertex[k];
  double n = 1.0, c = 0.0, before = 0.0;
  Index roots[64];
  int count = 0;
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) {
    const Index j = laplacian_.neighbors[i];
    if (in_cut_[j]) {
      c += 1.0;
      continue;
    }
    const Index r = region_root(j);
    if (std::find(roots, roots + count, r) != roots + count || count == 64) continue;
    roots[count++] = r;
    n += uf_size_[r];
    c += uf_constraints_[r] - 1.0;  // v stops being one of its constraints
    before += uf_size_[r] * uf_size_[r] + uf_constraints_[r] * uf_constraints_[r];
  }
  return n * n + c * c - before;
}

void AdaptiveCut::recover(NodeId k) {
  const Index v = h_.node_vertex[k];
  const Index r = region_root(v);
  const double n = uf_size_[r], c = uf_constraints_[r];
  const double n2 = n - 1.0, c2 = n2 > 0.0 ? c + 1.0 : 0.0;  // a region of one vanishes
  estimate_ += n2 * n2 + c2 * c2 - n * n - c * c;
  uf_size_[r] = n2;
  uf_constraints_[r] = c2;
  est_region_[v] = kNone;
  cut_.recover(k);
  in_cut_[v] = true;
  enqueue_neighbours(k);
}

void AdaptiveCut::unrecover(NodeId k) {
  const Index v = h_.node_vertex[k];
  estimate_ += delta_unrecover(k);
  const Index fresh = static_cast<Index>(uf_parent_.size());
  uf_parent_.push_back(fresh);
  uf_size_.push_back(1.0);
  uf_constraints_.push_back(0.0);
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) {
    const Index j = laplacian_.neighbors[i];
    if (in_cut_[j]) {
      uf_constraints_[fresh] += 1.0;
      continue;
    }
    const Index r = region_root(j);
    if (r == fresh) continue;
    uf_parent_[r] = fresh;
    uf_size_[fresh] += uf_size_[r];
    uf_constraints_[fresh] += uf_constraints_[r] - 1.0;
  }
  est_region_[v] = fresh;
  cut_.remove(k);
  in_cut_[v] = false;
  enqueue_neighbours(k);
}

void AdaptiveCut::rebuild_regions() {
  regions_ = find_regions(laplacian_, in_cut_);
  estimate_ = regions_.performance_estimate();
  est_region_ = regions_.region_of;
  uf_parent_.resize(regions_.count());
  uf_size_.resize(regions_.count());
  uf_constraints_.resize(regions_.count());
  for (Index r = 0; r < regions_.count(); ++r) {
    uf_parent_[r] = r;
    uf_size_[r] = static_cast<double>(regions_.size(r));
    uf_constraints_[r] = static_cast<double>(regions_.constraints[r]);
  }
}

std::size_t AdaptiveCut::update(const std::vector<Vec3>& positions, std::size_t eval_budget, std::size_t move_budget) {
  const std::size_t nodes = h_.node_count();
  if (nodes == 0 || threshold_ <= 0.0 || threshold_ == kInfinity) return 0;
  for (std::size_t i = 0; i < std::min(eval_budget, nodes); ++i) {
    const NodeId k = static_cast<NodeId>(next_eval_);
    next_eval_ = (next_eval_ + 1) % nodes;
    const double s = evaluate(k, positions);
    if (s < 0.0) continue;
    score_[k] = s;
    enqueue(k);
  }

  std::size_t moves = 0;
  // Over budget: recover the mildest nodes until the estimate fits.
  while (estimate_ > threshold_) {
    const NodeId a = top_recoverable();
    if (a == kNone) break;
    recover(a);
    ++moves;
  }
  // Under budget: give the most acute node to optimisation, alone if it fits,
  // else paired with recovering the mildest (thesis §3.3 pair moves).
  while (moves < move_budget) {
    const NodeId b = top_removable();
    if (b == kNone) break;
    const double grow = delta_unrecover(b);
    if (estimate_ + grow <= threshold_) {
      unrecover(b);
      ++moves;
      continue;
    }
    // Swap only for a clear gain, so that scores that shift a little from
    // frame to frame do not make the cut oscillate.
    const NodeId a = top_recoverable();
    if (a == kNone || !(score_[b] > kSwapGain * score_[a] + 1e-9)) break;
    const double before = estimate_;
    unrecover(b);
    if (!cut_.can_recover(a)) {  // b was a's parent: undo and stop
      recover(b);
      ++moves;
      break;
    }
    recover(a);
    moves += 2;
    if (estimate_ > threshold_) {  // the pair does not fit after all: undo it
      unrecover(a);
      recover(b);
      estimate_ = std::max(estimate_, before);
      break;
    }
  }
  if (moves > 0) rebuild_regions();
  return moves;
}

}  // namespace filigree
