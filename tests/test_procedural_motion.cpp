// Procedural motions as maps of space (DESIGN §2.3, issue 10 item 6): the field
// poses the base exactly as procedural_pose does, the older motions keep their
// poses, phase 0 is the identity, and each motion does what it says — the fold
// turns the far side a quarter turn, keeps the near side, and bends the band
// without compressing or shearing it, and the 360° twist turns a full turn
// end to end.

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "runtime/procedural_motion.h"

namespace filigree {
namespace {

constexpr Motion kMotions[] = {Motion::kBend, Motion::kTwist, Motion::kWave, Motion::kBump, Motion::kFold, Motion::kTwist360};

// n random points in the box [lo, lo + extent], plus its corners (so the box
// is exactly the reference's bbox).
std::vector<Vec3> cloud(const Vec3& lo, const Vec3& extent, int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Vec3> out;
  for (int k = 0; k < 8; ++k) out.push_back(lo + Vec3(k & 1, (k >> 1) & 1, (k >> 2) & 1).cwiseProduct(extent));
  for (int i = 0; i < n; ++i) out.push_back(lo + Vec3(u(rng), u(rng), u(rng)).cwiseProduct(extent));
  std::shuffle(out.begin(), out.end(), rng);
  return out;
}

double max_distance(const std::vector<Vec3>& x, const std::vector<Vec3>& y) {
  double d = 0.0;
  for (std::size_t i = 0; i < x.size(); ++i) d = std::max(d, (x[i] - y[i]).norm());
  return d;
}

// procedural_pose as it was before the field (bump by vertex index), kept as
// the plain reference for the motions that existed then.
std::vector<Vec3> legacy_pose(const std::vector<Vec3>& rest, Motion motion, double phase) {
  std::vector<Vec3> out = rest;
  Vec3 lo = rest[0], hi = rest[0];
  for (const Vec3& p : rest) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Vec3 extent = hi - lo, center = 0.5 * (lo + hi);
  int a = 0;
  extent.maxCoeff(&a);
  const int b = extent[(a + 1) % 3] >= extent[(a + 2) % 3] ? (a + 1) % 3 : (a + 2) % 3;
  const int c = 3 - a - b;
  const double half = std::max(0.5 * extent[a], 1e-300), diag = extent.norm();
  for (Vec3& p : out) {
    const double s = (p[a] - center[a]) / half;
    if (motion == Motion::kBend)
      p = Eigen::AngleAxisd(phase * (std::numbers::pi / 3.0) * std::pow(std::max(s, 0.0), 2.0), Vec3::Unit(c)) *
              (p - center) + center;
    if (motion == Motion::kTwist)
      p = Eigen::AngleAxisd(phase * (std::numbers::pi / 4.0) * s, Vec3::Unit(a)) * (p - center) + center;
    if (motion == Motion::kWave)
      p += Vec3::Unit(b) * (0.03 * diag * std::sin(std::numbers::pi * (s + 2.0 * phase)) * std::min(1.0, 4.0 * phase));
  }
  if (motion == Motion::kBump) {
    const auto top = std::max_element(rest.begin(), rest.end(), [&](const Vec3& x, const Vec3& y) { return x[b] < y[b]; });
    const double radius = 0.15 * diag;
    for (std::size_t i = 0; i < rest.size(); ++i) {
      const double d = (rest[i] - *top).norm() / radius;
      if (d < 1.0) out[i] += Vec3::Unit(b) * (phase * 0.05 * diag * (1.0 - d * d) * (1.0 - d * d));
    }
  }
  return out;
}

TEST(ProceduralMotion, NamesRoundTrip) {
  for (Motion m : kMotions) EXPECT_EQ(parse_motion(to_string(m)), m) << to_string(m);
  EXPECT_FALSE(parse_motion("crumple"));
}

TEST(ProceduralMotion, PoseIsTheFieldOnItsOwnPoints) {
  const std::vector<Vec3> rest = cloud(Vec3(-1, 2, 0.5), Vec3(2, 5, 3), 400, 1);
  for (Motion m : kMotions)
    for (double phase : {0.25, 1.0}) {
      const MotionField field(rest, m, phase);
      const std::vector<Vec3> pose = procedural_pose(rest, m, phase).positions;
      for (std::size_t i = 0; i < rest.size(); ++i) ASSERT_EQ(pose[i], field(rest[i])) << to_string(m) << " " << i;
      // A phase change keeps the frame: the same as a field built at that phase.
      const MotionField other = MotionField(rest, m, 0.5).with_phase(phase);
      for (const Vec3& p : rest) ASSERT_EQ(other(p), field(p)) << to_string(m);
    }
}

TEST(ProceduralMotion, OlderMotionsKeepTheirPoses) {
  // Three axis orders, so every choice of longest / next axis is exercised.
  for (const Vec3& extent : {Vec3(1, 3, 2), Vec3(3, 2, 1), Vec3(2, 1, 3)}) {
    const std::vector<Vec3> rest = cloud(Vec3(0.3, -2, 1), extent, 600, 2);
    for (Motion m : {Motion::kBend, Motion::kTwist, Motion::kWave, Motion::kBump})
      for (double phase : {0.1, 0.6, 1.0})
        EXPECT_EQ(max_distance(procedural_pose(rest, m, phase).positions, legacy_pose(rest, m, phase)), 0.0)
            << to_string(m) << " phase " << phase;
  }
}

TEST(ProceduralMotion, PhaseZeroIsTheIdentity) {
  const std::vector<Vec3> rest = cloud(Vec3(-3, 1, 2), Vec3(4, 1.5, 2.5), 500, 3);
  const double diag = bounding_box_diagonal(rest);
  for (Motion m : kMotions) {
    const MotionField field(rest, m, 0.0);
    EXPECT_LE(max_distance(field.apply(rest), rest), 1e-14 * diag) << to_string(m);
    // Points outside the reference's box too.
    for (const Vec3& p : {Vec3(-10, 0, 0), Vec3(5, 7, -9)}) EXPECT_LE((field(p) - p).norm(), 1e-14 * diag) << to_string(m);
  }
}

TEST(ProceduralMotion, AFieldOfTheWholePosesAnySubsetAlike) {
  // The bench poses the base vertices with the field of the whole mesh: each
  // point's image must not depend on which other points are mapped with it.
  const std::vector<Vec3> whole = cloud(Vec3(0, 0, 0), Vec3(1, 2, 4), 800, 4);
  std::vector<Vec3> subset;
  std::vector<std::size_t> ids;
  for (std::size_t i = whole.size(); i-- > 0;)
    if (i % 7 == 3) subset.push_back(whole[i]), ids.push_back(i);
  for (Motion m : kMotions) {
    const MotionField field(whole, m, 1.0);
    const std::vector<Vec3> all = field.apply(whole), part = field.apply(subset);
    for (std::size_t k = 0; k < ids.size(); ++k) ASSERT_EQ(part[k], all[ids[k]]) << to_string(m);
  }
}

// The fold's frame for the box [0,4]×[0,2]×[0,1]: a = x, b = y, c = z, the
// band is x ∈ [1, 3] and the fibre lies on y = 2.
class FoldTest : public ::testing::Test {
 protected:
  const std::vector<Vec3> box = cloud(Vec3(0, 0, 0), Vec3(4, 2, 1), 2000, 5);
  static Vec3 turn(const Vec3& d, double angle) { return Eigen::AngleAxisd(angle, Vec3::UnitZ()) * d; }
};

TEST_F(FoldTest, TurnsTheFarSideAQuarterTurnAndKeepsTheNearSide) {
  for (double phase : {0.5, 1.0}) {
    const MotionField fold(box, Motion::kFold, phase);
    ASSERT_EQ(fold.frame().a, 0);
    ASSERT_EQ(fold.frame().b, 1);
    std::vector<Vec3> far;
    int near = 0;
    for (const Vec3& p : box) {
      if (p.x() <= 1.0) {
        EXPECT_EQ(fold(p), p);
        ++near;
      }
      if (p.x() >= 3.0) far.push_back(p);
    }
    ASSERT_GT(near, 100);
    ASSERT_GT(far.size(), 100u);
    // Rigid on the far side: every difference turns by phase · 90° about +z
    // (+x towards +y).
    const double angle = phase * std::numbers::pi / 2.0;
    for (std::size_t i = 1; i < far.size(); ++i)
      ASSERT_LE((fold(far[i]) - fold(far[0]) - turn(far[i] - far[0], angle)).norm(), 1e-12) << i;
    // Continuous at the band's ends.
    for (double x : {1.0, 3.0}) {
      const Vec3 p(x, 0.7, 0.4), e(1e-9, 0, 0);
      EXPECT_LE((fold(p + e) - fold(p - e)).norm(), 1e-8);
    }
  }
}

TEST_F(FoldTest, BendsTheBandWithoutCompressingOrShearing) {
  const MotionField fold(box, Motion::kFold, 1.0);
  const double h = 1e-5;
  auto jacobian = [&](const Vec3& p) {
    Eigen::Matrix3d j;
    for (int k = 0; k < 3; ++k) j.col(k) = (fold(p + h * Vec3::Unit(k)) - fold(p - h * Vec3::Unit(k))) / (2 * h);
    return j;
  };
  double largest_stretch = 0.0;
  for (const Vec3& p : box) {
    if (p.x() < 1.0 + 2 * h || p.x() > 3.0 - 2 * h) continue;
    const Eigen::Matrix3d j = jacobian(p);
    // Across the fibre and along c: lengths and right angles kept (no shear).
    EXPECT_NEAR(j.col(1).norm(), 1.0, 1e-8);
    EXPECT_NEAR((j.col(2) - Vec3::UnitZ()).norm(), 0.0, 1e-8);
    EXPECT_NEAR(j.col(0).dot(j.col(1)), 0.0, 1e-8);
    EXPECT_NEAR(j.col(0).dot(j.col(2)), 0.0, 1e-8);
    // Along the fibre: stretched by 1 − y·θ' ≥ 1, never compressed or inverted.
    EXPECT_GE(j.determinant(), 1.0 - 1e-8);
    largest_stretch = std::max(largest_stretch, j.determinant());
    // The fibre itself (y = 2) keeps its length.
    const Vec3 on_fibre(p.x(), 2.0, p.z());
    EXPECT_NEAR(jacobian(on_fibre).col(0).norm(), 1.0, 1e-8) << p.x();
  }
  // It does bend: θ' peaks at 1.5 · 90° / 2 in the middle, so the face at y = 0 stretches ~3.4×.
  EXPECT_GT(largest_stretch, 3.0);
}

TEST(ProceduralMotion, BendKeepsTheNearHalfAndTwistTurnsAboutTheLongAxis) {
  const std::vector<Vec3> rest = cloud(Vec3(1, -1, 0), Vec3(2, 6, 3), 800, 6);  // a = y, b = z, c = x
  const double diag = bounding_box_diagonal(rest);
  const MotionField bend(rest, Motion::kBend, 1.0), twist(rest, Motion::kTwist, 1.0);
  const Vec3 center = twist.frame().center;
  int moved = 0;
  for (const Vec3& p : rest) {
    const double s = (p.y() - center.y()) / 3.0;
    if (s <= 0.0) {
      EXPECT_LE((bend(p) - p).norm(), 1e-14 * diag);
    }
    if (s > 0.5) moved += (bend(p) - p).norm() > 1e-3 * diag;
    // Twist: a turn of 45° · s about the y axis through the centre.
    const Vec3 q = twist(p) - center, r = p - center;
    EXPECT_NEAR(q.y(), r.y(), 1e-12 * diag);
    EXPECT_NEAR(std::hypot(q.x(), q.z()), std::hypot(r.x(), r.z()), 1e-12 * diag);
    if (std::hypot(r.x(), r.z()) > 0.1) {
      const double turned = std::remainder(std::atan2(q.x(), q.z()) - std::atan2(r.x(), r.z()), 2 * std::numbers::pi);
      EXPECT_NEAR(turned, std::numbers::pi / 4.0 * s, 1e-9);
    }
  }
  EXPECT_GT(moved, 100);
}

// The angle a point at radius r from the long axis y (through `center`) turns
// through about it, unwrapped along the axis from s = −1 to s = 1: the twist's
// end-to-end angle. In 400 steps no step turns by half a turn for any twist
// under 200 turns, so atan2's wrap cannot hide a turn.
double end_to_end_angle(const MotionField& twist, const Vec3& center, double half, double r) {
  double total = 0.0, previous = 0.0;
  constexpr int kSteps = 400;
  for (int k = 0; k <= kSteps; ++k) {
    const double s = -1.0 + 2.0 * k / kSteps;
    const Vec3 p = center + Vec3(r, s * half, 0.0);  // off the axis along +x
    const Vec3 q = twist(p) - center;
    const double angle = std::atan2(q.x(), q.z()) - std::atan2(r, 0.0);
    if (k > 0) total += std::remainder(angle - previous, 2 * std::numbers::pi);
    previous = angle;
  }
  return total;
}

TEST(ProceduralMotion, Twist360TurnsAFullTurnEndToEnd) {
  const std::vector<Vec3> rest = cloud(Vec3(1, -1, 0), Vec3(2, 6, 3), 800, 8);  // a = y
  const MotionField twist(rest, Motion::kTwist360, 1.0), quarter(rest, Motion::kTwist, 1.0);
  const Vec3 center = twist.frame().center;
  ASSERT_EQ(twist.frame().a, 1);
  const double half = twist.frame().half;
  // 360° end to end at full strength (−180° at s = −1, +180° at s = 1), half
  // of it at phase ½; kTwist's 90° measured alike, as a check of the measure.
  EXPECT_NEAR(end_to_end_angle(twist, center, half, 0.7), 2 * std::numbers::pi, 1e-9);
  EXPECT_NEAR(end_to_end_angle(twist.with_phase(0.5), center, half, 0.7), std::numbers::pi, 1e-9);
  EXPECT_NEAR(end_to_end_angle(quarter, center, half, 0.7), std::numbers::pi / 2, 1e-9);
  const double diag = bounding_box_diagonal(rest);
  for (const Vec3& p : rest) {
    // A rotation about the long axis by 180° · s: lengths along and across it kept.
    const double s = (p.y() - center.y()) / half;
    const Vec3 q = twist(p) - center, r = p - center;
    EXPECT_NEAR(q.y(), r.y(), 1e-12 * diag);
    EXPECT_NEAR(std::hypot(q.x(), q.z()), std::hypot(r.x(), r.z()), 1e-12 * diag);
    if (std::hypot(r.x(), r.z()) > 0.1) {
      const double turned = std::remainder(std::atan2(q.x(), q.z()) - std::atan2(r.x(), r.z()), 2 * std::numbers::pi);
      EXPECT_NEAR(std::remainder(turned - std::numbers::pi * s, 2 * std::numbers::pi), 0.0, 1e-9);
    }
  }
}

TEST(ProceduralMotion, BumpIsLocalAroundItsCentre) {
  const std::vector<Vec3> rest = cloud(Vec3(0, 0, 0), Vec3(3, 1, 2), 3000, 7);  // a = x, b = z
  const MotionField bump(rest, Motion::kBump, 0.8);
  const MotionFrame& f = bump.frame();
  ASSERT_EQ(f.b, 2);
  for (const Vec3& p : rest) EXPECT_LE(p.z(), f.bump_center.z());
  EXPECT_NEAR(f.diagonal, std::sqrt(14.0), 1e-12);
  // The centre rises by 0.8 · 5% of the diagonal along +b; beyond 15% of the
  // diagonal nothing moves; in between every point rises, less further out.
  EXPECT_NEAR((bump(f.bump_center) - f.bump_center - Vec3(0, 0, 0.04 * f.diagonal)).norm(), 0.0, 1e-12);
  int inside = 0;
  for (const Vec3& p : rest) {
    const double d = (p - f.bump_center).norm(), rise = bump(p).z() - p.z();
    EXPECT_EQ(bump(p).head<2>(), p.head<2>());
    if (d >= 0.15 * f.diagonal) {
      EXPECT_EQ(bump(p), p);
    } else {
      EXPECT_GT(rise, 0.0);
      ++inside;
    }
    const Vec3 further = f.bump_center + (p - f.bump_center) * 1.1;
    if (d > 0 && d < 0.13 * f.diagonal) {
      EXPECT_LT(bump(further).z() - further.z(), rise);
    }
  }
  EXPECT_GT(inside, 10);
}

}  // namespace
}  // namespace filigree
