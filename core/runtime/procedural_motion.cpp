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
  return std::nullopt;
}

const char* to_string(Motion m) {
  switch (m) {
    case Motion::kBend: return "bend";
    case Motion::kTwist: return "twist";
    case Motion::kWave: return "wave";
    case Motion::kBump: return "bump";
  }
  return "?";
}

Pose procedural_pose(const std::vector<Vec3>& rest, Motion motion, double phase) {
  Pose pose{rest};
  if (rest.empty()) return pose;
  Vec3 lo = rest[0], hi = rest[0];
  for (const Vec3& p : rest) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Vec3 extent = hi - lo, center = 0.5 * (lo + hi);
  // Axes by extent: a longest, b next, c the rest.
  int a = 0;
  extent.maxCoeff(&a);
  const int b = extent[(a + 1) % 3] >= extent[(a + 2) % 3] ? (a + 1) % 3 : (a + 2) % 3;
  const int c = 3 - a - b;
  const double half = std::max(0.5 * extent[a], 1e-300), diag = extent.norm();
  const Vec3 axis_c = Vec3::Unit(c), axis_a = Vec3::Unit(a), axis_b = Vec3::Unit(b);

  for (Vec3& p : pose.positions) {
    const double s = (p[a] - center[a]) / half;  // −1 … 1 along the longest axis
    switch (motion) {
      case Motion::kBend: {
        const double angle = phase * (std::numbers::pi / 3.0) * std::pow(std::max(s, 0.0), 2.0);
        p = Eigen::AngleAxisd(angle, axis_c) * (p - center) + center;
        break;
      }
      case Motion::kTwist: {
        const double angle = phase * (std::numbers::pi / 4.0) * s;
        p = Eigen::AngleAxisd(angle, axis_a) * (p - center) + center;
        break;
      }
      case Motion::kWave:
        p += axis_b * (0.03 * diag * std::sin(std::numbers::pi * (s + 2.0 * phase)) * std::min(1.0, 4.0 * phase));
        break;
      case Motion::kBump:
        break;
    }
  }
  if (motion == Motion::kBump) {
    // The rest vertex furthest along +b, and a smooth falloff within 15% of the diagonal.
    const auto top = std::max_element(rest.begin(), rest.end(), [&](const Vec3& x, const Vec3& y) { return x[b] < y[b]; });
    const double radius = 0.15 * diag;
    for (std::size_t i = 0; i < rest.size(); ++i) {
      const double d = (rest[i] - *top).norm() / radius;
      if (d < 1.0) pose.positions[i] += axis_b * (phase * 0.05 * diag * (1.0 - d * d) * (1.0 - d * d));
    }
  }
  return pose;
}

}  // namespace filigree
