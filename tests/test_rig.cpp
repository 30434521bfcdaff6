// The rig: its small accessors, validate_rig's every rejection, restricting
// it to a subset of vertices, and the rig file (round trips, and damage of
// every kind turned into a RigError that names the input).

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "skinning/rig.h"
#include "skinning/rig_file.h"

namespace filigree {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

Mat4 affine(double angle, const Vec3& axis, const Vec3& t) {
  Mat4 m = Mat4::Identity();
  m.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  m.topRightCorner<3, 1>() = t;
  return m;
}

// Three joints in a chain, four bindings (joint 1 bound twice), five vertices
// (vertex 2 without influences), two clips covering every path and
// interpolation.
Rig sample_rig() {
  Rig rig;
  Joint root;
  root.name = "root";
  root.rest.translation = Vec3(0, 1, 0);
  root.root_parent = affine(0.3, Vec3(0, 1, 0), Vec3(0, 0, 2));
  Joint arm;
  arm.name = "arm";
  arm.parent = 0;
  arm.rest.rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Vec3(1, 2, 3).normalized()));
  arm.rest.scale = Vec3(1, 2, 0.5);
  Joint hand;
  hand.name = "hand";
  hand.parent = 1;
  hand.rest.translation = Vec3(0.3, 0, 0);
  rig.joints = {root, arm, hand};

  rig.bindings = {{0, Mat4::Identity()},
                  {1, affine(-0.2, Vec3(1, 0, 0), Vec3(0, -1, 0))},
                  {2, affine(0.7, Vec3(0, 0, 1), Vec3(-0.3, -1, 0.1))},
                  {1, affine(1.1, Vec3(1, 1, 0), Vec3(0.5, 0, 0))}};

  rig.weights.offsets = {0, 1, 3, 3, 6, 7};
  rig.weights.binding = {0, 1, 2, 3, 0, 2, 2};
  rig.weights.weight = {1.0f, 0.25f, 0.75f, 0.5f, 0.25f, 0.25f, 1.0f};
  for (int v = 0; v < 5; ++v) rig.bind_positions.push_back(Vec3(v, 2.0 * v - 1, 0.1 * v * v));

  ClipChannel rotation;
  rotation.joint = 1;
  rotation.path = ClipChannel::Path::kRotation;
  rotation.interpolation = ClipChannel::Interpolation::kLinear;
  rotation.times = {0.0f, 0.5f, 1.5f};
  rotation.values = {0, 0, 0, 1, 0, 0, 0.70710677f, 0.70710677f, 0, 0, 1, 0};
  ClipChannel translation;
  translation.joint = 2;
  translation.path = ClipChannel::Path::kTranslation;
  translation.interpolation = ClipChannel::Interpolation::kCubicSpline;
  translation.times = {0.25f, 2.0f};
  translation.values = {0.1f, 0.2f, 0.3f, 1, 2, 3, 0.4f, 0.5f, 0.6f, -0.1f, -0.2f, -0.3f, 4, 5, 6, -0.4f, -0.5f, -0.6f};
  ClipChannel scale;
  scale.joint = 0;
  scale.path = ClipChannel::Path::kScale;
  scale.interpolation = ClipChannel::Interpolation::kStep;
  scale.times = {0.0f, 1.0f};
  scale.values = {1, 1, 1, 2, 2, 2};
  rig.clips = {{"wave", {rotation, translation}}, {"idle", {scale}}};
  return rig;
}

void expect_same_rig(const Rig& a, const Rig& b) {
  ASSERT_EQ(a.joints.size(), b.joints.size());
  for (std::size_t j = 0; j < a.joints.size(); ++j) {
    SCOPED_TRACE("joint " + std::to_string(j));
    EXPECT_EQ(a.joints[j].name, b.joints[j].name);
    EXPECT_EQ(a.joints[j].parent, b.joints[j].parent);
    EXPECT_EQ(a.joints[j].rest.translation, b.joints[j].rest.translation);
    EXPECT_EQ(a.joints[j].rest.rotation.coeffs(), b.joints[j].rest.rotation.coeffs());
    EXPECT_EQ(a.joints[j].rest.scale, b.joints[j].rest.scale);
    EXPECT_EQ(a.joints[j].root_parent, b.joints[j].root_parent);
  }
  ASSERT_EQ(a.bindings.size(), b.bindings.size());
  for (std::size_t i = 0; i < a.bindings.size(); ++i) {
    EXPECT_EQ(a.bindings[i].joint, b.bindings[i].joint) << "binding " << i;
    EXPECT_EQ(a.bindings[i].inverse_bind, b.bindings[i].inverse_bind) << "binding " << i;
  }
  EXPECT_EQ(a.weights.offsets, b.weights.offsets);
  EXPECT_EQ(a.weights.binding, b.weights.binding);
  EXPECT_EQ(a.weights.weight, b.weights.weight);
  ASSERT_EQ(a.bind_positions.size(), b.bind_positions.size());
  for (std::size_t v = 0; v < a.bind_positions.size(); ++v) EXPECT_EQ(a.bind_positions[v], b.bind_positions[v]) << "vertex " << v;
  ASSERT_EQ(a.clips.size(), b.clips.size());
  for (std::size_t c = 0; c < a.clips.size(); ++c) {
    SCOPED_TRACE("clip " + std::to_string(c));
    EXPECT_EQ(a.clips[c].name, b.clips[c].name);
    ASSERT_EQ(a.clips[c].channels.size(), b.clips[c].channels.size());
    for (std::size_t k = 0; k < a.clips[c].channels.size(); ++k) {
      const ClipChannel &x = a.clips[c].channels[k], &y = b.clips[c].channels[k];
      EXPECT_EQ(x.joint, y.joint);
      EXPECT_EQ(x.path, y.path);
      EXPECT_EQ(x.interpolation, y.interpolation);
      EXPECT_EQ(x.times, y.times);
      EXPECT_EQ(x.values, y.values);
    }
  }
}

std::string error_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const RigError& e) {
    return e.what();
  }
  return "no error";
}

void put_u32(std::string& bytes, std::size_t at, std::uint32_t v) { std::memcpy(bytes.data() + at, &v, 4); }
std::uint32_t get_u32(const std::string& bytes, std::size_t at) {
  std::uint32_t v;
  std::memcpy(&v, bytes.data() + at, 4);
  return v;
}

// Offsets in sample_rig()'s bytes, from the layout rig_file.h documents.
constexpr std::size_t kJointCountAt = 12;
std::size_t binding_count_at(const Rig& rig) {
  std::size_t at = kJointCountAt + 4;
  for (const Joint& j : rig.joints) at += 4 + j.name.size() + 4 + 8 * (3 + 4 + 3 + 16);
  return at;
}
std::size_t vertex_count_at(const Rig& rig) { return binding_count_at(rig) + 4 + rig.bindings.size() * (4 + 8 * 16); }

std::filesystem::path temp_file(const std::string& name) {
  return std::filesystem::path(::testing::TempDir()) / ("filigree_" + std::to_string(::getpid()) + "_" + name);
}

// --- the accessors ---

TEST(Rig, JointTransformMatrixIsTranslationRotationScale) {
  JointTransform t;
  t.translation = Vec3(1, 2, 3);
  t.rotation = Eigen::Quaterniond(std::sqrt(0.5), 0, 0, std::sqrt(0.5));  // 90° about z
  t.scale = Vec3(2, 3, 4);
  // Columns: R·(2,0,0) = (0,2,0), R·(0,3,0) = (−3,0,0), R·(0,0,4) = (0,0,4).
  Mat4 expected;
  expected << 0, -3, 0, 1,  //
      2, 0, 0, 2,           //
      0, 0, 4, 3,           //
      0, 0, 0, 1;
  EXPECT_LT((t.matrix() - expected).cwiseAbs().maxCoeff(), 1e-12) << t.matrix();
  EXPECT_EQ(JointTransform{}.matrix(), Mat4::Identity());
}

TEST(Rig, DurationIsTheLastKeyOverAllChannels) {
  const Rig rig = sample_rig();
  EXPECT_DOUBLE_EQ(rig.clips[0].duration(), 2.0);
  EXPECT_DOUBLE_EQ(rig.clips[1].duration(), 1.0);
  EXPECT_EQ(AnimationClip{}.duration(), 0.0);
}

TEST(Rig, ClipByName) {
  const Rig rig = sample_rig();
  EXPECT_EQ(rig.clip("wave"), &rig.clips[0]);
  EXPECT_EQ(rig.clip("idle"), &rig.clips[1]);
  EXPECT_EQ(rig.clip("run"), nullptr);
  EXPECT_EQ(rig.clip(""), nullptr);
}

// --- validate_rig ---

TEST(ValidateRig, AcceptsTheSampleRigAndAnEmptyOne) {
  EXPECT_NO_THROW(validate_rig(sample_rig()));
  EXPECT_NO_THROW(validate_rig(Rig{}));
}

struct BadCase {
  const char* name;
  std::function<void(Rig&)> damage;
  const char* expected;  // a part of the message
};

TEST(ValidateRig, RejectsEachBadCaseSayingWhatAndWhere) {
  const std::vector<BadCase> cases = {
      {"weights not normalised", [](Rig& r) { r.weights.weight[2] = 0.45f; }, "vertex 1: weights sum to 0.7, not 1"},
      {"negative weight", [](Rig& r) { r.weights.weight[1] = -0.25f, r.weights.weight[2] = 1.25f; }, "vertex 1: weight -0.25 is negative"},
      {"NaN weight", [](Rig& r) { r.weights.weight[6] = std::numeric_limits<float>::quiet_NaN(); }, "vertex 4: weight nan"},
      {"binding out of range", [](Rig& r) { r.weights.binding[0] = 4; }, "vertex 0: influence 0 names binding 4"},
      {"binding's joint out of range", [](Rig& r) { r.bindings[3].joint = 3; }, "binding 3: joint 3 does not exist"},
      {"parent after child", [](Rig& r) { r.joints[1].parent = 2; }, "joint 1 'arm': parent 2 does not come before it"},
      {"parent is itself", [](Rig& r) { r.joints[1].parent = 1; }, "joint 1 'arm': parent 1 does not come before it"},
      {"parent below -1", [](Rig& r) { r.joints[2].parent = -2; }, "joint 2 'hand': parent -2"},
      {"NaN inverse bind", [](Rig& r) { r.bindings[1].inverse_bind(2, 3) = kNaN; }, "binding 1: inverse bind matrix is not finite"},
      {"NaN root parent", [](Rig& r) { r.joints[0].root_parent(0, 0) = kNaN; }, "joint 0 'root': root parent transform is not finite"},
      {"infinite translation", [](Rig& r) { r.joints[2].rest.translation.x() = INFINITY; }, "joint 2 'hand' rest: translation is not finite"},
      {"NaN scale", [](Rig& r) { r.joints[1].rest.scale.y() = kNaN; }, "joint 1 'arm' rest: scale is not finite"},
      {"NaN rotation", [](Rig& r) { r.joints[1].rest.rotation.w() = kNaN; }, "joint 1 'arm' rest: rotation is not finite"},
      {"zero-norm rotation", [](Rig& r) { r.joints[0].rest.rotation.coeffs().setZero(); }, "joint 0 'root' rest: rotation has norm 0, not 1"},
      {"non-unit rotation", [](Rig& r) { r.joints[0].rest.rotation.coeffs() *= 2; }, "rotation has norm 2, not 1"},
      {"equal clip times", [](Rig& r) { r.clips[0].channels[0].times[1] = 0.0f; }, "clip 0 'wave' channel 0 (rotation): key times do not increase at key 1"},
      {"decreasing clip times", [](Rig& r) { r.clips[1].channels[0].times = {1.0f, 0.5f}; }, "clip 1 'idle' channel 0 (scale): key times do not increase at key 1"},
      {"NaN clip time", [](Rig& r) { r.clips[0].channels[1].times[0] = std::numeric_limits<float>::quiet_NaN(); }, "key 0 time is not finite"},
      {"no keys", [](Rig& r) { r.clips[1].channels[0].times.clear(), r.clips[1].channels[0].values.clear(); }, "clip 1 'idle' channel 0 (scale): no keys"},
      {"a value missing", [](Rig& r) { r.clips[0].channels[0].values.pop_back(); }, "11 values for 3 keys, expected 12"},
      {"cubic spline without tangents", [](Rig& r) { r.clips[0].channels[1].values.resize(6); }, "6 values for 2 keys, expected 18"},
      {"NaN value", [](Rig& r) { r.clips[0].channels[1].values[13] = std::numeric_limits<float>::quiet_NaN(); }, "value 13 (key 1) is not finite"},
      {"channel joint out of range", [](Rig& r) { r.clips[1].channels[0].joint = 3; }, "clip 1 'idle' channel 0 (scale): joint 3 does not exist"},
      {"unknown path", [](Rig& r) { r.clips[1].channels[0].path = static_cast<ClipChannel::Path>(7); }, "unknown path 7"},
      {"unknown interpolation", [](Rig& r) { r.clips[1].channels[0].interpolation = static_cast<ClipChannel::Interpolation>(9); }, "unknown interpolation 9"},
      {"NaN bind position", [](Rig& r) { r.bind_positions[3].z() = kNaN; }, "vertex 3: bind position is not finite"},
      {"offsets decrease", [](Rig& r) { r.weights.offsets[2] = 0; }, "vertex 1: influence offsets decrease"},
      {"offsets end early", [](Rig& r) { r.weights.offsets[5] = 6; }, "offsets end at 6, not at the 7 influences"},
      {"offsets do not start at 0", [](Rig& r) { r.weights.offsets[0] = 1; }, "offsets start at 1"},
      {"no offsets", [](Rig& r) { r.weights.offsets.clear(); }, "no offsets"},
      {"binding and weight counts differ", [](Rig& r) { r.weights.weight.push_back(0); }, "7 binding indices but 8 weights"},
      {"bind positions missing", [](Rig& r) { r.bind_positions.pop_back(); }, "weights cover 5 vertices but there are 4 bind positions"},
  };
  for (const BadCase& c : cases) {
    Rig rig = sample_rig();
    c.damage(rig);
    const std::string error = error_of([&] { validate_rig(rig); });
    EXPECT_NE(error.find(c.expected), std::string::npos) << c.name << ": got \"" << error << "\", expected it to contain \"" << c.expected << "\"";
  }
}

TEST(ValidateRig, JointLimitIs65535) {
  Rig rig;
  rig.joints.resize(65535);
  EXPECT_NO_THROW(validate_rig(rig));
  rig.joints.emplace_back();
  EXPECT_NE(error_of([&] { validate_rig(rig); }).find("65536 joints"), std::string::npos);
}

// --- restricted_to ---

TEST(Rig, RestrictedToPicksTheVerticesInOrder) {
  const Rig rig = sample_rig();
  const Rig sub = rig.restricted_to({4, 1, 2, 1, 0});
  EXPECT_EQ(sub.weights.offsets, (std::vector<std::uint32_t>{0, 1, 3, 3, 5, 6}));
  EXPECT_EQ(sub.weights.binding, (std::vector<std::uint32_t>{2, 1, 2, 1, 2, 0}));
  EXPECT_EQ(sub.weights.weight, (std::vector<float>{1.0f, 0.25f, 0.75f, 0.25f, 0.75f, 1.0f}));
  ASSERT_EQ(sub.bind_positions.size(), 5u);
  EXPECT_EQ(sub.bind_positions[0], rig.bind_positions[4]);
  EXPECT_EQ(sub.bind_positions[1], rig.bind_positions[1]);
  EXPECT_EQ(sub.bind_positions[2], rig.bind_positions[2]);
  EXPECT_EQ(sub.bind_positions[3], rig.bind_positions[1]);
  EXPECT_EQ(sub.bind_positions[4], rig.bind_positions[0]);
  EXPECT_EQ(sub.vertex_count(), 5u);
  // Joints, bindings and clips are the whole rig's.
  Rig expected = rig;
  expected.weights = sub.weights;
  expected.bind_positions = sub.bind_positions;
  expect_same_rig(sub, expected);
  EXPECT_NO_THROW(validate_rig(sub));
}

TEST(Rig, RestrictedToNothingIsAnEmptyValidRig) {
  const Rig sub = sample_rig().restricted_to({});
  EXPECT_EQ(sub.vertex_count(), 0u);
  EXPECT_EQ(sub.weights.offsets, std::vector<std::uint32_t>{0});
  EXPECT_EQ(sub.joints.size(), 3u);
  EXPECT_NO_THROW(validate_rig(sub));
}

TEST(Rig, RestrictedToAnIdOutOfRangeThrows) {
  const Rig rig = sample_rig();
  const std::string error = error_of([&] { rig.restricted_to({0, 5}); });
  EXPECT_NE(error.find("id 1 is vertex 5, but the rig has 5 vertices"), std::string::npos) << error;
}

// --- the rig file ---

TEST(RigFile, RoundTripIsFieldByFieldEqual) {
  const Rig rig = sample_rig();
  const std::string bytes = serialize_rig(rig);
  expect_same_rig(deserialize_rig(bytes), rig);
}

TEST(RigFile, EmptyRigRoundTrips) {
  const std::string bytes = serialize_rig(Rig{});
  // Magic, version, then the joint, binding and vertex counts, the one
  // offset, the influence and clip counts: all zero.
  EXPECT_EQ(bytes.size(), 8u + 4 + 4 + 4 + 4 + 4 + 4 + 4);
  expect_same_rig(deserialize_rig(bytes), Rig{});
}

TEST(RigFile, IsDeterministic) {
  const std::string bytes = serialize_rig(sample_rig());
  EXPECT_EQ(serialize_rig(sample_rig()), bytes);
  EXPECT_EQ(serialize_rig(deserialize_rig(bytes)), bytes);
}

TEST(RigFile, LayoutIsTheDocumentedOne) {
  const Rig rig = sample_rig();
  const std::string bytes = serialize_rig(rig);
  EXPECT_EQ(bytes.substr(0, 8), std::string("FLGRIG\0\0", 8));
  EXPECT_EQ(get_u32(bytes, 8), kRigFormatVersion);
  EXPECT_EQ(get_u32(bytes, kJointCountAt), 3u);
  EXPECT_EQ(get_u32(bytes, kJointCountAt + 4), 4u);  // "root"
  EXPECT_EQ(bytes.substr(kJointCountAt + 8, 4), "root");
  EXPECT_EQ(get_u32(bytes, binding_count_at(rig)), 4u);
  EXPECT_EQ(get_u32(bytes, vertex_count_at(rig)), 5u);
  // Joint 1 ("arm"): name, parent 0, translation, then rotation x y z w.
  const std::size_t arm = kJointCountAt + 4 + (4 + 4 + 4 + 8 * 26);
  EXPECT_EQ(get_u32(bytes, arm), 3u);
  EXPECT_EQ(bytes.substr(arm + 4, 3), "arm");
  EXPECT_EQ(get_u32(bytes, arm + 7), 0u);
  double q[4];
  std::memcpy(q, bytes.data() + arm + 7 + 4 + 24, sizeof q);
  const Eigen::Quaterniond& r = rig.joints[1].rest.rotation;
  EXPECT_EQ(q[0], r.x());
  EXPECT_EQ(q[3], r.w());
}

TEST(RigFile, EveryTruncationThrowsRigError) {
  const std::string bytes = serialize_rig(sample_rig());
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    const std::string error = error_of([&] { deserialize_rig(std::string_view(bytes).substr(0, n), "cut.rig"); });
    ASSERT_EQ(error.rfind("cut.rig: ", 0), 0u) << "length " << n << ": " << error;
    ASSERT_NE(error.find("truncated"), std::string::npos) << "length " << n << ": " << error;
  }
}

TEST(RigFile, EveryFlippedByteIsAnErrorOrAValidRig) {
  const std::string bytes = serialize_rig(sample_rig());
  int errors = 0;
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    std::string damaged = bytes;
    damaged[i] = static_cast<char>(damaged[i] ^ 0xA5);
    try {
      const Rig read = deserialize_rig(damaged, "flip.rig");
      validate_rig(read);
      // Accepted: then it is the rig those bytes encode, nothing dropped or guessed.
      EXPECT_EQ(serialize_rig(read), damaged) << "byte " << i << " accepted but read as another rig";
      EXPECT_GE(i, 4u) << "a damaged magic was accepted";
    } catch (const RigError& e) {
      ASSERT_EQ(std::string(e.what()).rfind("flip.rig: ", 0), 0u) << e.what();
      ++errors;
    }
  }
  EXPECT_GT(errors, 0);
}

TEST(RigFile, TrailingBytesAreRejected) {
  const std::string bytes = serialize_rig(sample_rig()) + '\0';
  EXPECT_NE(error_of([&] { deserialize_rig(bytes, "x.rig"); }).find("x.rig: corrupt: 1 unexpected bytes after the rig"), std::string::npos);
}

TEST(RigFile, BadMagicIsRejected) {
  std::string bytes = serialize_rig(sample_rig());
  bytes[3] ^= 1;
  EXPECT_EQ(error_of([&] { deserialize_rig(bytes, "x.rig"); }), "x.rig: not a Filigree rig file (bad magic)");
  EXPECT_EQ(error_of([&] { deserialize_rig("hello", "x.rig"); }), "x.rig: not a Filigree rig file (bad magic)");
  EXPECT_NE(error_of([&] { deserialize_rig(std::string("FLG"), "x.rig"); }).find("x.rig: truncated"), std::string::npos);
  EXPECT_NE(error_of([&] { deserialize_rig("", "x.rig"); }).find("x.rig: truncated"), std::string::npos);
}

TEST(RigFile, UnknownVersionIsRejected) {
  for (std::uint32_t version : {0u, 2u, 0x01000000u}) {
    std::string bytes = serialize_rig(sample_rig());
    put_u32(bytes, 8, version);
    EXPECT_EQ(error_of([&] { deserialize_rig(bytes, "x.rig"); }),
              "x.rig: unknown format version " + std::to_string(version) + " (this build reads version 1)");
  }
}

TEST(RigFile, HugeCountsAreRejectedBeforeAllocating) {
  const Rig rig = sample_rig();
  const std::string good = serialize_rig(rig);
  for (std::size_t at : {kJointCountAt, binding_count_at(rig), vertex_count_at(rig)}) {
    std::string bytes = good;
    put_u32(bytes, at, 0xFFFFFFFFu);
    const std::string error = error_of([&] { deserialize_rig(bytes, "x.rig"); });
    EXPECT_EQ(error.rfind("x.rig: count too large: 4294967295 ", 0), 0u) << error;
  }
}

TEST(RigFile, DeserializedRigIsValidated) {
  std::string bytes = serialize_rig(sample_rig());
  // Joint 0's parent follows its name ("root", 4 bytes).
  put_u32(bytes, kJointCountAt + 4 + 4 + 4, 5);
  EXPECT_EQ(error_of([&] { deserialize_rig(bytes, "x.rig"); }), "x.rig: invalid rig: joint 0 'root': parent 5 does not come before it");
}

TEST(RigFile, InvalidRigIsNotSerialized) {
  Rig rig = sample_rig();
  rig.weights.weight[0] = 0.5f;
  EXPECT_NE(error_of([&] { serialize_rig(rig); }).find("vertex 0: weights sum to 0.5"), std::string::npos);
}

TEST(RigFile, SaveAndLoad) {
  const std::filesystem::path path = temp_file("save_and_load.rig");
  const Rig rig = sample_rig();
  save_rig(Rig{}, path);
  save_rig(rig, path);  // replaces the first
  expect_same_rig(load_rig(path), rig);
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".partial"));
  EXPECT_EQ(std::filesystem::file_size(path), serialize_rig(rig).size());
  std::filesystem::remove(path);
}

TEST(RigFile, LoadErrorsNameTheFile) {
  const std::filesystem::path missing = temp_file("missing.rig");
  EXPECT_EQ(error_of([&] { load_rig(missing); }).rfind(missing.string() + ": ", 0), 0u);

  const std::filesystem::path cut = temp_file("cut.rig");
  const std::string bytes = serialize_rig(sample_rig());
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() - 3);
  const std::string error = error_of([&] { load_rig(cut); });
  EXPECT_EQ(error.rfind(cut.string() + ": ", 0), 0u) << error;
  EXPECT_NE(error.find("truncated"), std::string::npos) << error;
  std::filesystem::remove(cut);
}

}  // namespace
}  // namespace filigree
