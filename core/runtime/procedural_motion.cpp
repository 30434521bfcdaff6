#include "runtime/procedural_motion.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/Geometry>

namespace filigree {

std::optional<Motion> parse_motion(const std::string& name) {
  if (name == "bend") return Motion::kBend;
  if (name == "twist") return Motion::kTwist;
  if (name == "wave") return Motion::kWave;
  if (name == "bump") return Motion::kBump;
  if (name == "fold") return Motion::kFold;
  if (name == "twist360") return Motion::kTwist360;
  return std::nullopt;
}

const char* to_string(Motion m) {
  switch (m) {
    case Motion::kBend: return "bend";
    case Motion::kTwist: return "twist";
    case Motion::kWave: return "wave";
    case Motion::kBump: return "bump";
    case Motion::kFold: return "fold";
    case Motion::kTwist360: return "twist360";
  }
  return "?";
}

namespace {

double smoothstep(double t) { return t * t * (3.0 - 2.0 * t); }

// ∫₀ᵗ (cos θ(τ) − 1, sin θ(τ)) dτ with θ(τ) = theta_max · smoothstep(τ): the fold's
// neutral fibre minus the straight one (per unit band length). No closed form;
// composite 5-point Gauss–Legendre over 8 panels is exact to rounding for this
// smooth integrand (error ~ (t/8)¹¹ · |f⁽¹⁰⁾| / 10¹²). cos θ − 1 is written as
// −2 sin²(θ/2) so a small phase keeps its precision and phase 0 is exactly 0.
Eigen::Vector2d fold_fibre_offset(double t, double theta_max) {
  static constexpr double kNode[5] = {-0.9061798459386639928, -0.5384693101056830910, 0.0,
                                      0.5384693101056830910, 0.9061798459386639928};
  static constexpr double kWeight[5] = {0.2369268850561890875, 0.4786286704993664680, 128.0 / 225.0,
                                        0.4786286704993664680, 0.2369268850561890875};
  constexpr int kPanels = 8;
  const double h = t / kPanels;
  double cos_minus_one = 0.0, sin_sum = 0.0;
  for (int k = 0; k < kPanels; ++k)
    for (int i = 0; i < 5; ++i) {
      const double theta = theta_max * smoothstep(h * (k + 0.5 * (kNode[i] + 1.0)));
      const double half_sin = std::sin(0.5 * theta);
      cos_minus_one += kWeight[i] * (-2.0 * half_sin * half_sin);
      sin_sum += kWeight[i] * std::sin(theta);
    }
  return 0.5 * h * Eigen::Vector2d(cos_minus_one, sin_sum);
}

}  // namespace

MotionField::MotionField(std::span<const Vec3> reference, Motion motion, double phase)
    : motion_(motion), phase_(phase), identity_(reference.empty()) {
  if (reference.empty()) return;
  MotionFrame& f = frame_;
  f.lo = f.hi = reference[0];
  for (const Vec3& p : reference) f.lo = f.lo.cwiseMin(p), f.hi = f.hi.cwiseMax(p);
  const Vec3 extent = f.hi - f.lo;
  f.center = 0.5 * (f.lo + f.hi);
  extent.maxCoeff(&f.a);
  f.b = extent[(f.a + 1) % 3] >= extent[(f.a + 2) % 3] ? (f.a + 1) % 3 : (f.a + 2) % 3;
  f.c = 3 - f.a - f.b;
  f.half = std::max(0.5 * extent[f.a], 1e-300);
  f.diagonal = extent.norm();
  // The first point furthest along +b (as procedural_pose has always chosen it).
  f.bump_center = *std::max_element(reference.begin(), reference.end(),
                                    [&](const Vec3& x, const Vec3& y) { return x[f.b] < y[f.b]; });
  if (motion_ == Motion::kFold) fold_end_ = fold_fibre_offset(1.0, phase_ * (std::numbers::pi / 2.0));
}

MotionField MotionField::with_phase(double phase) const {
  MotionField out = *this;
  out.phase_ = phase;
  if (motion_ == Motion::kFold) out.fold_end_ = fold_fibre_offset(1.0, phase * (std::numbers::pi / 2.0));
  return out;
}

std::vector<Vec3> MotionField::apply(std::span<const Vec3> points) const {
  std::vector<Vec3> out(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) out[i] = (*this)(points[i]);
  return out;
}

// Fold (issue 10 item 6): beam bending in the a–b plane, not a rotation about a
// point, so no shear. The neutral fibre lies on the bbox face at hi[b] and runs
// along a; across the band s ∈ [−½, ½] (length L = half the length) its angle
// rises as θ = phase · 90° · smoothstep(t), t = 0 … 1, and stays beyond it. A
// point keeps its distance y = p[b] − hi[b] from the fibre along the fibre's
// normal. The Jacobian determinant is 1 − y·θ', ≥ 1 inside the reference's box
// (y ≤ 0): the outside of the fold stretches, nothing is compressed or turned
// inside out however thick the mesh (a centred fibre would invert the inside of
// a mesh thicker than ~0.4 of its length, such as the Armadillo). θ' → 0 at the
// band's ends keeps that stretch continuous (the map is C¹). Beyond the band:
// s ≤ −½ fixed, s ≥ ½ rotated rigidly by θ about c.
Vec3 MotionField::fold(const Vec3& p) const {
  const MotionFrame& f = frame_;
  const double length = f.half;
  const double x = p[f.a] - (f.center[f.a] - 0.5 * length);  // along a from the band's start
  const double x_band = std::clamp(x, 0.0, length);
  const double t = x_band / length;
  const double theta_max = phase_ * (std::numbers::pi / 2.0);
  const double theta = theta_max * smoothstep(t);
  // Beyond the band the offset is the band's end (cached: the far quarter of the length is there).
  const Eigen::Vector2d fibre = length * (t < 1.0 ? fold_fibre_offset(t, theta_max) : fold_end_);
  const double y = p[f.b] - f.hi[f.b];
  const double half_sin = std::sin(0.5 * theta);
  const double cos_minus_one = -2.0 * half_sin * half_sin, sin_theta = std::sin(theta);
  Vec3 out = p;
  out[f.a] += fibre[0] + (x - x_band) * cos_minus_one - y * sin_theta;
  out[f.b] += fibre[1] + (x - x_band) * sin_theta + y * cos_minus_one;
  return out;
}

// Bend, twist, wave and bump are computed exactly as procedural_pose did before
// it was written over this field (same operations, same order), so demos,
// tests and recorded numbers keep their poses bit for bit.
Vec3 MotionField::operator()(const Vec3& p) const {
  if (identity_) return p;
  const MotionFrame& f = frame_;
  const double s = (p[f.a] - f.center[f.a]) / f.half;  // −1 … 1 along the longest axis
  switch (motion_) {
    case Motion::kBend: {
      const double angle = phase_ * (std::numbers::pi / 3.0) * std::pow(std::max(s, 0.0), 2.0);
      return Eigen::AngleAxisd(angle, Vec3::Unit(f.c)) * (p - f.center) + f.center;
    }
    case Motion::kTwist: {
      const double angle = phase_ * (std::numbers::pi / 4.0) * s;
      return Eigen::AngleAxisd(angle, Vec3::Unit(f.a)) * (p - f.center) + f.center;
    }
    case Motion::kWave:
      return p + Vec3::Unit(f.b) * (0.03 * f.diagonal * std::sin(std::numbers::pi * (s + 2.0 * phase_)) *
                                    std::min(1.0, 4.0 * phase_));
    case Motion::kBump: {
      // A smooth radial falloff within 15% of the diagonal around the bump centre.
      const double radius = 0.15 * f.diagonal;
      const double d = (p - f.bump_center).norm() / radius;
      if (!(d < 1.0)) return p;  // also a NaN d (no extent), as before
      return p + Vec3::Unit(f.b) * (phase_ * 0.05 * f.diagonal * (1.0 - d * d) * (1.0 - d * d));
    }
    case Motion::kFold:
      return fold(p);
    case Motion::kTwist360: {
      const double angle = phase_ * std::numbers::pi * s;
      return Eigen::AngleAxisd(angle, Vec3::Unit(f.a)) * (p - f.center) + f.center;
    }
  }
  return p;
}

Pose procedural_pose(const std::vector<Vec3>& rest, Motion motion, double phase) {
  return Pose{MotionField(rest, motion, phase).apply(rest)};
}

}  // namespace filigree
