// Sampling animation clips (glTF 2.0 interpolation): key values at key times,
// linear/slerp and cubic Hermite between them, clamping outside, shortest
// rotation paths. Expected values are worked out here, not by the sampler.

#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "skinning/animation_clip.h"
#include "skinning/rig.h"

namespace filigree {
namespace {

using Path = ClipChannel::Path;
using Interp = ClipChannel::Interpolation;

constexpr double kPi = 3.14159265358979323846;
double deg(double d) { return d * kPi / 180; }

ClipChannel channel(std::uint32_t joint, Path path, Interp interp, std::vector<float> times, std::vector<float> values) {
  ClipChannel ch;
  ch.joint = joint;
  ch.path = path;
  ch.interpolation = interp;
  ch.times = std::move(times);
  ch.values = std::move(values);
  return ch;
}

AnimationClip clip_of(std::vector<ClipChannel> channels) { return AnimationClip{"clip", std::move(channels)}; }

std::vector<JointTransform> sample(const AnimationClip& clip, double t, std::size_t joints = 1) {
  std::vector<JointTransform> local(joints);
  sample_clip(clip, t, local);
  return local;
}

// x y z w of a rotation by `angle` about `axis`, computed by hand.
std::vector<double> axis_angle_xyzw(Vec3 axis, double angle) {
  axis.normalize();
  const double s = std::sin(angle / 2);
  return {axis.x() * s, axis.y() * s, axis.z() * s, std::cos(angle / 2)};
}

// q and −q are the same rotation: compare after aligning the sign.
void expect_rotation(const Eigen::Quaterniond& q, const std::vector<double>& xyzw, double tol = 1e-6) {
  const double got[4] = {q.x(), q.y(), q.z(), q.w()};
  double dot = 0;
  for (int i = 0; i < 4; ++i) dot += got[i] * xyzw[i];
  const double sign = dot < 0 ? -1 : 1;
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(sign * got[i], xyzw[i], tol) << "component " << i << " of " << q.coeffs().transpose();
  EXPECT_NEAR(q.norm(), 1.0, 1e-12);
}

void expect_vec(const Vec3& v, const Vec3& expected, double tol = 1e-6) {
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(v[i], expected[i], tol) << "component " << i << " of " << v.transpose();
}

const Vec3& property(const JointTransform& t, Path path) { return path == Path::kTranslation ? t.translation : t.scale; }

// --- key values at key times ---

const std::vector<float> kTimes = {0.5f, 1.25f, 2.0f, 4.0f};

// Per key: the value, and (cubic splines) tangents that differ from it.
std::vector<float> vector_values(Interp interp) {
  std::vector<float> out;
  for (int k = 0; k < 4; ++k) {
    const float v[3] = {1.5f * k - 1, 2.0f - k * k, 0.25f * k + 3};
    if (interp == Interp::kCubicSpline)
      for (float c : v) out.push_back(c + 7);  // in-tangent
    out.insert(out.end(), v, v + 3);
    if (interp == Interp::kCubicSpline)
      for (float c : v) out.push_back(-5 * c);  // out-tangent
  }
  return out;
}

std::vector<double> key_rotation(int k) { return axis_angle_xyzw(Vec3(1, k, 2 - k), deg(40.0 * k + 10)); }

std::vector<float> rotation_values(Interp interp) {
  std::vector<float> out;
  for (int k = 0; k < 4; ++k) {
    const std::vector<double> q = key_rotation(k);
    if (interp == Interp::kCubicSpline)
      for (int i = 0; i < 4; ++i) out.push_back(static_cast<float>(0.3 * i - 1));
    for (double c : q) out.push_back(static_cast<float>(c));
    if (interp == Interp::kCubicSpline)
      for (int i = 0; i < 4; ++i) out.push_back(static_cast<float>(2 - i));
  }
  return out;
}

class KeyTimes : public ::testing::TestWithParam<Interp> {};

TEST_P(KeyTimes, TranslationAndScaleEqualTheKeyValues) {
  for (Path path : {Path::kTranslation, Path::kScale}) {
    const AnimationClip clip = clip_of({channel(0, path, GetParam(), kTimes, vector_values(GetParam()))});
    for (int k = 0; k < 4; ++k) {
      SCOPED_TRACE("key " + std::to_string(k));
      expect_vec(property(sample(clip, kTimes[k])[0], path), Vec3(1.5 * k - 1, 2.0 - k * k, 0.25 * k + 3), 1e-12);
    }
  }
}

TEST_P(KeyTimes, RotationEqualsTheKeyValue) {
  const AnimationClip clip = clip_of({channel(0, Path::kRotation, GetParam(), kTimes, rotation_values(GetParam()))});
  for (int k = 0; k < 4; ++k) {
    SCOPED_TRACE("key " + std::to_string(k));
    expect_rotation(sample(clip, kTimes[k])[0].rotation, key_rotation(k));
  }
}

TEST_P(KeyTimes, ClampsBeforeTheFirstAndAfterTheLastKey) {
  const AnimationClip translation = clip_of({channel(0, Path::kTranslation, GetParam(), kTimes, vector_values(GetParam()))});
  const AnimationClip rotation = clip_of({channel(0, Path::kRotation, GetParam(), kTimes, rotation_values(GetParam()))});
  for (double t : {-std::numeric_limits<double>::infinity(), -3.0, 0.0, 0.4999}) {
    expect_vec(sample(translation, t)[0].translation, Vec3(-1, 2, 3), 1e-12);
    expect_rotation(sample(rotation, t)[0].rotation, key_rotation(0));
  }
  for (double t : {4.0001, 100.0, std::numeric_limits<double>::infinity()}) {
    expect_vec(sample(translation, t)[0].translation, Vec3(3.5, -7, 3.75), 1e-12);
    expect_rotation(sample(rotation, t)[0].rotation, key_rotation(3));
  }
}

TEST_P(KeyTimes, OneKeyHoldsEverywhere) {
  const int per_key = GetParam() == Interp::kCubicSpline ? 9 : 3;
  std::vector<float> values(per_key, 0.0f);
  values[per_key == 9 ? 3 : 0] = 4;
  values[per_key == 9 ? 4 : 1] = 5;
  values[per_key == 9 ? 5 : 2] = 6;
  if (per_key == 9) values[0] = values[8] = 11;  // tangents play no part
  const AnimationClip clip = clip_of({channel(0, Path::kScale, GetParam(), {1.0f}, values)});
  for (double t : {-1.0, 1.0, 1.5, 30.0}) expect_vec(sample(clip, t)[0].scale, Vec3(4, 5, 6), 1e-12);
}

INSTANTIATE_TEST_SUITE_P(AllInterpolations, KeyTimes, ::testing::Values(Interp::kStep, Interp::kLinear, Interp::kCubicSpline),
                         [](const ::testing::TestParamInfo<Interp>& info) {
                           return info.param == Interp::kStep ? std::string("Step") : info.param == Interp::kLinear ? std::string("Linear") : std::string("CubicSpline");
                         });

// --- step ---

TEST(SampleClip, StepHoldsTheKeyAtOrBefore) {
  const AnimationClip clip = clip_of({channel(0, Path::kTranslation, Interp::kStep, {0.0f, 1.0f, 2.0f}, {0, 0, 0, 1, 1, 1, 2, 2, 2})});
  expect_vec(sample(clip, 0.999)[0].translation, Vec3(0, 0, 0), 0);
  expect_vec(sample(clip, 1.0)[0].translation, Vec3(1, 1, 1), 0);
  expect_vec(sample(clip, 1.5)[0].translation, Vec3(1, 1, 1), 0);
  expect_vec(sample(clip, 1.999)[0].translation, Vec3(1, 1, 1), 0);
}

// --- linear ---

TEST(SampleClip, LinearTranslationAndScaleLerp) {
  // Keys at 1 and 3: t = 1.5 is a quarter of the way, t = 2 halfway.
  for (Path path : {Path::kTranslation, Path::kScale}) {
    const AnimationClip clip = clip_of({channel(0, path, Interp::kLinear, {1.0f, 3.0f}, {0, 1, 2, 4, -1, 6})});
    expect_vec(property(sample(clip, 1.5)[0], path), Vec3(1, 0.5, 3), 1e-12);
    expect_vec(property(sample(clip, 2.0)[0], path), Vec3(2, 0, 4), 1e-12);
    expect_vec(property(sample(clip, 2.9)[0], path), Vec3(3.8, -0.9, 5.8), 1e-12);
  }
}

std::vector<float> as_floats(const std::vector<double>& a, const std::vector<double>& b) {
  std::vector<float> out;
  for (double c : a) out.push_back(static_cast<float>(c));
  for (double c : b) out.push_back(static_cast<float>(c));
  return out;
}

TEST(SampleClip, LinearRotationIsSlerp) {
  // About one axis slerp turns the angle linearly: 0° → 90° over [0, 2].
  const AnimationClip z = clip_of({channel(0, Path::kRotation, Interp::kLinear, {0.0f, 2.0f},
                                           as_floats(axis_angle_xyzw(Vec3::UnitZ(), 0), axis_angle_xyzw(Vec3::UnitZ(), deg(90))))});
  expect_rotation(sample(z, 1.0)[0].rotation, axis_angle_xyzw(Vec3::UnitZ(), deg(45)));
  expect_rotation(sample(z, 0.5)[0].rotation, axis_angle_xyzw(Vec3::UnitZ(), deg(22.5)));

  const Vec3 axis(1, 2, 2);
  const AnimationClip tilted = clip_of({channel(0, Path::kRotation, Interp::kLinear, {1.0f, 2.0f},
                                                as_floats(axis_angle_xyzw(axis, deg(20)), axis_angle_xyzw(axis, deg(140))))});
  expect_rotation(sample(tilted, 1.3)[0].rotation, axis_angle_xyzw(axis, deg(20 + 0.3 * 120)));

  // Different axes: the slerp formula sin((1−s)θ)/sin θ · q0 + sin(sθ)/sin θ · q1.
  const std::vector<double> q0 = axis_angle_xyzw(Vec3(1, 0, 0), deg(60)), q1 = axis_angle_xyzw(Vec3(0, 1, 1), deg(100));
  const AnimationClip general = clip_of({channel(0, Path::kRotation, Interp::kLinear, {0.0f, 1.0f}, as_floats(q0, q1))});
  double dot = 0;
  for (int i = 0; i < 4; ++i) dot += q0[i] * q1[i];
  ASSERT_GT(dot, 0);
  const double theta = std::acos(dot), s = 0.7;
  std::vector<double> expected(4);
  for (int i = 0; i < 4; ++i) expected[i] = (std::sin((1 - s) * theta) * q0[i] + std::sin(s * theta) * q1[i]) / std::sin(theta);
  expect_rotation(sample(general, s)[0].rotation, expected, 1e-6);
}

TEST(SampleClip, LinearRotationTakesTheShortestPath) {
  // Keys 10° and 80° about z, the second stored as −q: the same rotation, so
  // halfway is 45°, not the long way round (which would pass through 225°).
  std::vector<double> q1 = axis_angle_xyzw(Vec3::UnitZ(), deg(80));
  for (double& c : q1) c = -c;
  const AnimationClip clip = clip_of({channel(0, Path::kRotation, Interp::kLinear, {0.0f, 1.0f}, as_floats(axis_angle_xyzw(Vec3::UnitZ(), deg(10)), q1))});
  expect_rotation(sample(clip, 0.5)[0].rotation, axis_angle_xyzw(Vec3::UnitZ(), deg(45)));
  expect_rotation(sample(clip, 0.25)[0].rotation, axis_angle_xyzw(Vec3::UnitZ(), deg(27.5)));
  // A rotated vector turns monotonically from 10° to 80°.
  double previous = deg(10) - 1e-9;
  for (int i = 0; i <= 20; ++i) {
    const Vec3 x = sample(clip, i / 20.0)[0].rotation * Vec3::UnitX();
    const double angle = std::atan2(x.y(), x.x());
    EXPECT_GE(angle, previous) << "at s = " << i / 20.0;
    EXPECT_LE(angle, deg(80) + 1e-6);
    previous = angle - 1e-9;
  }
}

TEST(SampleClip, LinearFindsTheRightKeyAmongMany) {
  // 257 unevenly spaced keys; the expected value comes from a linear scan.
  std::vector<float> times, values;
  for (int k = 0; k <= 256; ++k) {
    times.push_back(static_cast<float>(k + 0.4 * std::sin(k)));
    values.insert(values.end(), {static_cast<float>(k * k), static_cast<float>(-k), static_cast<float>(std::cos(k))});
  }
  const AnimationClip clip = clip_of({channel(0, Path::kTranslation, Interp::kLinear, times, values)});
  for (int i = 0; i < 1000; ++i) {
    const double t = -2 + 262.0 * i / 999.0;
    Vec3 expected;
    if (t <= times.front()) {
      expected = Vec3(values[0], values[1], values[2]);
    } else if (t >= times.back()) {
      expected = Vec3(values[768], values[769], values[770]);
    } else {
      std::size_t k = 0;
      while (!(times[k] <= t && t < times[k + 1])) ++k;
      const double s = (t - times[k]) / (static_cast<double>(times[k + 1]) - times[k]);
      for (int c = 0; c < 3; ++c) expected[c] = (1 - s) * values[3 * k + c] + s * values[3 * k + 3 + c];
    }
    expect_vec(sample(clip, t)[0].translation, expected, 1e-6 * (1 + expected.norm()));
  }
}

// --- cubic spline ---

std::vector<float> cubic_keys(const Vec3& a0, const Vec3& v0, const Vec3& b0, const Vec3& a1, const Vec3& v1, const Vec3& b1) {
  std::vector<float> out;
  for (const Vec3* v : {&a0, &v0, &b0, &a1, &v1, &b1})
    for (int i = 0; i < 3; ++i) out.push_back(static_cast<float>((*v)[i]));
  return out;
}

TEST(SampleClip, CubicSplineWithZeroTangentsIsSmoothstep) {
  const Vec3 zero = Vec3::Zero(), v1(2, 4, -8);
  for (Path path : {Path::kTranslation, Path::kScale}) {
    const AnimationClip clip = clip_of({channel(0, path, Interp::kCubicSpline, {0.0f, 2.0f}, cubic_keys(zero, zero, zero, zero, v1, zero))});
    for (double s : {0.25, 0.5, 0.8}) {
      const double h = 3 * s * s - 2 * s * s * s;
      expect_vec(property(sample(clip, 2 * s)[0], path), h * v1, 1e-12);
    }
  }
  // Rotations: the same blend of the components, normalised.
  const std::vector<double> q0 = axis_angle_xyzw(Vec3::UnitZ(), 0), q1 = axis_angle_xyzw(Vec3::UnitZ(), deg(90));
  std::vector<float> values;
  for (const std::vector<double>* q : {&q0, &q1}) {
    values.insert(values.end(), 4, 0.0f);
    for (double c : *q) values.push_back(static_cast<float>(c));
    values.insert(values.end(), 4, 0.0f);
  }
  const AnimationClip rotation = clip_of({channel(0, Path::kRotation, Interp::kCubicSpline, {0.0f, 2.0f}, values)});
  for (double s : {0.25, 0.5}) {
    const double h = 3 * s * s - 2 * s * s * s;
    std::vector<double> expected(4);
    double norm = 0;
    for (int i = 0; i < 4; ++i) norm += std::pow((1 - h) * q0[i] + h * q1[i], 2);
    for (int i = 0; i < 4; ++i) expected[i] = ((1 - h) * q0[i] + h * q1[i]) / std::sqrt(norm);
    expect_rotation(sample(rotation, 2 * s)[0].rotation, expected);
  }
}

TEST(SampleClip, CubicSplineTangentsAreScaledByTheKeyInterval) {
  // Keys at 1 and 3 (td = 2), both values 0: only b0 (x) and a1 (y) act;
  // a0 and b1 lie outside the interval and must play no part.
  const Vec3 big(100, 100, 100);
  const AnimationClip clip = clip_of({channel(0, Path::kTranslation, Interp::kCubicSpline, {1.0f, 3.0f},
                                              cubic_keys(big, Vec3::Zero(), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3::Zero(), -big))});
  // x = (s³ − 2s² + s)·td, y = (s³ − s²)·td.
  expect_vec(sample(clip, 2.0)[0].translation, Vec3(0.25, -0.25, 0), 1e-12);
  expect_vec(sample(clip, 1.5)[0].translation, Vec3(0.28125, -0.09375, 0), 1e-12);
}

TEST(SampleClip, CubicSplineFullHermite) {
  // All four terms at once, s = 0.6 between keys 0.5 and 1.5 (td = 1).
  const Vec3 v0(1, -2, 0.5), b0(3, 1, -1), a1(-2, 0.5, 4), v1(-1, 2, 3);
  const AnimationClip clip = clip_of({channel(0, Path::kTranslation, Interp::kCubicSpline, {0.5f, 1.5f},
                                              cubic_keys(Vec3::Zero(), v0, b0, a1, v1, Vec3::Zero()))});
  const double s = 0.6, s2 = s * s, s3 = s2 * s;
  const Vec3 expected = (2 * s3 - 3 * s2 + 1) * v0 + (s3 - 2 * s2 + s) * b0 + (-2 * s3 + 3 * s2) * v1 + (s3 - s2) * a1;
  expect_vec(sample(clip, 1.1)[0].translation, expected, 1e-6);
}

// --- what gets written, and errors ---

TEST(SampleClip, OverwritesOnlyAnimatedProperties) {
  std::vector<JointTransform> local(3);
  for (std::size_t j = 0; j < 3; ++j) {
    local[j].translation = Vec3(j, 10.0 + j, 20);
    local[j].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * (j + 1), Vec3::UnitY()));
    local[j].scale = Vec3(1, 2, 3 + j);
  }
  const std::vector<JointTransform> before = local;
  const AnimationClip clip = clip_of({channel(1, Path::kRotation, Interp::kStep, {0.0f}, {0, 0, 1, 0}),
                                      channel(2, Path::kScale, Interp::kLinear, {0.0f, 1.0f}, {1, 1, 1, 3, 3, 3})});
  sample_clip(clip, 0.5, local);
  for (std::size_t j = 0; j < 3; ++j) EXPECT_EQ(local[j].translation, before[j].translation) << j;
  EXPECT_EQ(local[0].rotation.coeffs(), before[0].rotation.coeffs());
  EXPECT_EQ(local[0].scale, before[0].scale);
  expect_rotation(local[1].rotation, {0, 0, 1, 0});
  EXPECT_EQ(local[1].scale, before[1].scale);
  EXPECT_EQ(local[2].rotation.coeffs(), before[2].rotation.coeffs());
  expect_vec(local[2].scale, Vec3(2, 2, 2), 1e-12);
}

TEST(SampleClip, EmptyClipChangesNothing) {
  std::vector<JointTransform> local(2);
  local[1].translation = Vec3(1, 2, 3);
  sample_clip(AnimationClip{}, 1.0, local);
  EXPECT_EQ(local[1].translation, Vec3(1, 2, 3));
  EXPECT_EQ(local[0].translation, Vec3::Zero());
}

TEST(SampleClip, JointOutOfRangeThrows) {
  const AnimationClip clip = clip_of({channel(3, Path::kTranslation, Interp::kLinear, {0.0f}, {1, 2, 3})});
  std::vector<JointTransform> local(3);
  EXPECT_THROW(sample_clip(clip, 0.0, local), RigError);
  local.resize(4);
  EXPECT_NO_THROW(sample_clip(clip, 0.0, local));
}

TEST(SampleClip, MalformedChannelsThrowInsteadOfReadingPastTheValues) {
  std::vector<JointTransform> local(1);
  EXPECT_THROW(sample_clip(clip_of({channel(0, Path::kRotation, Interp::kLinear, {0.0f, 1.0f}, {0, 0, 0, 1, 0, 0})}), 0.5, local), RigError);
  EXPECT_THROW(sample_clip(clip_of({channel(0, Path::kTranslation, Interp::kCubicSpline, {0.0f, 1.0f}, {0, 0, 0, 1, 1, 1})}), 0.5, local), RigError);
  EXPECT_THROW(sample_clip(clip_of({channel(0, Path::kScale, Interp::kStep, {}, {})}), 0.5, local), RigError);
  EXPECT_THROW(sample_clip(clip_of({channel(0, Path::kScale, Interp::kStep, {0.0f}, {1, 1, 1})}), std::nan(""), local), RigError);
}

}  // namespace
}  // namespace filigree
