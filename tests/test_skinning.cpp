// Skinning (LBS, dual quaternions), skeletal poses, and glTF skins read and
// written (issue 13). Expected values are computed here by hand, not by the
// code under test.

#include <cmath>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include "mesh/gltf_io.h"
#include "mesh/mesh_io.h"
#include "skinning/auto_rig.h"
#include "skinning/skinning.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

Mat4 translation(const Vec3& t) {
  Mat4 m = Mat4::Identity();
  m.topRightCorner<3, 1>() = t;
  return m;
}

Mat4 rotation_about(const Vec3& axis, double angle, const Vec3& centre = Vec3::Zero()) {
  Mat4 r = Mat4::Identity();
  r.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  return translation(centre) * r * translation(-centre);
}

// Two joints along x; one vertex half on each.
Rig two_bone_rig(std::vector<Vec3> points, std::vector<float> weight_on_second) {
  Rig rig;
  rig.joints.resize(2);
  rig.joints[0].name = "a";
  rig.joints[1].name = "b";
  rig.joints[1].parent = 0;
  rig.joints[1].rest.translation = Vec3(1, 0, 0);
  rig.bindings = {{0, Mat4::Identity()}, {1, translation(Vec3(-1, 0, 0))}};
  rig.bind_positions = std::move(points);
  for (const float w : weight_on_second) {
    rig.weights.binding.insert(rig.weights.binding.end(), {0, 1});
    rig.weights.weight.insert(rig.weights.weight.end(), {1.0f - w, w});
    rig.weights.offsets.push_back(static_cast<std::uint32_t>(rig.weights.binding.size()));
  }
  validate_rig(rig);
  return rig;
}

TEST(Skinning, ModelTransformsComposeParentsAndHonourModelOverrides) {
  const Rig rig = two_bone_rig({Vec3(1, 0, 0)}, {0.5f});
  SkeletonPose pose = SkeletonPose::rest(rig);
  pose.local[0].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
  std::vector<Mat4> m = model_transforms(rig, pose);
  // Joint b sits at (1,0,0) in a's frame, so at (0,1,0) once a turns 90° about z.
  EXPECT_LT((m[1].topRightCorner<3, 1>() - Vec3(0, 1, 0)).norm(), 1e-12);
  pose.model[1] = translation(Vec3(5, 6, 7));
  m = model_transforms(rig, pose);
  EXPECT_LT((m[1] - translation(Vec3(5, 6, 7))).norm(), 1e-12);
}

TEST(Skinning, LinearBlendIsTheWeightedSumOfSkinningMatrices) {
  const std::vector<Vec3> points = {Vec3(0.2, 0.3, 0.0), Vec3(1.5, -0.2, 0.1), Vec3(1.0, 0.5, 0.5)};
  const std::vector<float> w = {0.0f, 1.0f, 0.25f};
  const Rig rig = two_bone_rig(points, w);
  SkeletonPose pose = SkeletonPose::rest(rig);
  pose.local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Vec3::UnitY()));
  pose.local[0].translation = Vec3(0.1, 0.2, 0.3);
  const std::vector<Mat4> model = model_transforms(rig, pose);
  std::vector<Vec3> out(points.size());
  skin(rig, model, SkinningMethod::kLinearBlend, out);
  // By hand: joint a = T(0.1,0.2,0.3); joint b = a · T(1,0,0) · R_y(0.7); B_b = T(−1,0,0).
  const Mat4 a = translation(Vec3(0.1, 0.2, 0.3));
  Mat4 ry = Mat4::Identity();
  ry.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.7, Vec3::UnitY()).toRotationMatrix();
  const Mat4 b = a * translation(Vec3(1, 0, 0)) * ry * translation(Vec3(-1, 0, 0));
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector4d x(points[i].x(), points[i].y(), points[i].z(), 1.0);
    const Eigen::Vector4d expected = (1.0 - w[i]) * (a * x) + double{w[i]} * (b * x);
    EXPECT_LT((out[i] - expected.head<3>()).norm(), 1e-6) << "vertex " << i;
  }
}

TEST(Skinning, DualQuaternionsKeepVolumeWhereLinearBlendCollapses) {
  // A point at radius 1 from the x axis, half on a joint twisted 180° about x:
  // LBS averages the point and its mirror (radius 0), DQS turns it 90°.
  const Rig rig = two_bone_rig({Vec3(1, 1, 0)}, {0.5f});
  SkeletonPose pose = SkeletonPose::rest(rig);
  pose.local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI, Vec3::UnitX()));
  const std::vector<Mat4> model = model_transforms(rig, pose);
  std::vector<Vec3> lbs(1), dqs(1);
  skin(rig, model, SkinningMethod::kLinearBlend, lbs);
  skin(rig, model, SkinningMethod::kDualQuaternion, dqs);
  EXPECT_LT(Vec3(0, lbs[0].y(), lbs[0].z()).norm(), 1e-9);
  EXPECT_NEAR(Vec3(0, dqs[0].y(), dqs[0].z()).norm(), 1.0, 1e-9);
  EXPECT_NEAR(dqs[0].x(), 1.0, 1e-9);
}

// Joints twisted +100° and −100° about x: the quaternions of their matrices
// (w > 0 for both: cos 50°, ±sin 50°) lie in opposite hemispheres (dot
// cos 100° < 0). Blended without bringing them to one hemisphere they
// cancel to no rotation at all (equal weights) or to the long way round; the
// right blend goes through ±180° (the short arc between them), and LBS
// averages the two rotated points. (At ±170° a matrix's quaternion already
// comes out in one hemisphere, so that case does not tell.) Expected values
// are computed here, independently.
TEST(Skinning, OppositeTwistsBlendThroughTheShortArc) {
  const Vec3 p(1, 1, 0);
  for (const float w : {0.5f, 0.25f}) {
    const Rig rig = two_bone_rig({p}, {w});
    SkeletonPose pose = SkeletonPose::rest(rig);
    const double twist = 100.0 * M_PI / 180.0;
    pose.model[0] = rotation_about(Vec3::UnitX(), twist);
    // Joint b's skinning matrix M·B is the −170° twist itself (its B is T(−1,0,0)).
    pose.model[1] = rotation_about(Vec3::UnitX(), -twist) * translation(Vec3(1, 0, 0));
    const std::vector<Mat4> model = model_transforms(rig, pose);
    std::vector<Vec3> lbs(1), dqs(1);
    skin(rig, model, SkinningMethod::kLinearBlend, lbs);
    skin(rig, model, SkinningMethod::kDualQuaternion, dqs);

    const Eigen::AngleAxisd a(twist, Vec3::UnitX()), b(-twist, Vec3::UnitX());
    const Vec3 lbs_expected = (1.0 - w) * (a * p) + double{w} * (b * p);
    EXPECT_LT((lbs[0] - lbs_expected).norm(), 1e-6) << "w " << w;

    Eigen::Quaterniond qa(a), qb(b);
    if (qa.dot(qb) < 0) qb.coeffs() = -qb.coeffs();  // one hemisphere: the short arc
    Eigen::Quaterniond blend;
    blend.coeffs() = (1.0 - w) * qa.coeffs() + double{w} * qb.coeffs();
    blend.normalize();
    const Vec3 dqs_expected = blend * p;
    EXPECT_LT((dqs[0] - dqs_expected).norm(), 1e-6) << "w " << w << ": got " << dqs[0].transpose();
    // The point keeps its distance from the axis, and has turned past 90°.
    EXPECT_NEAR(Vec3(0, dqs[0].y(), dqs[0].z()).norm(), 1.0, 1e-6);
    EXPECT_LT(dqs[0].y(), -0.5) << "w " << w << ": blended through the long arc";
  }
}

TEST(Skinning, DualQuaternionsOfOneRigidInfluenceApplyItExactly) {
  const Rig rig = two_bone_rig({Vec3(0.3, -0.4, 2.0)}, {1.0f});
  SkeletonPose pose = SkeletonPose::rest(rig);
  const Mat4 target = rotation_about(Vec3(1, 2, 3), 1.1, Vec3(0.5, 0.5, 0.5)) * translation(Vec3(0.2, 0, -1));
  pose.model[1] = target;
  std::vector<Vec3> out(1);
  skin(rig, model_transforms(rig, pose), SkinningMethod::kDualQuaternion, out);
  const Eigen::Vector4d expected = target * translation(Vec3(-1, 0, 0)) * Eigen::Vector4d(0.3, -0.4, 2.0, 1.0);
  EXPECT_LT((out[0] - expected.head<3>()).norm(), 1e-9);
}

TEST(Skinning, RestPoseGivesBindPositionsWhenInverseBindsMatchTheRest) {
  const TriMesh tube = test::capped_tube(12, 8);
  const Rig rig = auto_rig(tube, {.joints = 3});
  std::vector<Vec3> out(tube.vertex_count());
  for (const SkinningMethod method : {SkinningMethod::kLinearBlend, SkinningMethod::kDualQuaternion}) {
    skin(rig, model_transforms(rig, SkeletonPose::rest(rig)), method, out);
    for (std::size_t i = 0; i < out.size(); ++i) ASSERT_LT((out[i] - tube.positions[i]).norm(), 1e-9) << i;
  }
}

TEST(Skinning, WrongSizesAreErrors) {
  const Rig rig = two_bone_rig({Vec3(0, 0, 0)}, {0.5f});
  std::vector<Vec3> out(2);
  const std::vector<Mat4> model(2, Mat4::Identity());
  EXPECT_THROW(skin(rig, model, SkinningMethod::kLinearBlend, out), RigError);
  out.resize(1);
  EXPECT_THROW(skin(rig, std::vector<Mat4>(1, Mat4::Identity()), SkinningMethod::kLinearBlend, out), RigError);
  SkeletonPose pose = SkeletonPose::rest(rig);
  pose.local.pop_back();
  EXPECT_THROW(model_transforms(rig, pose), RigError);
}

TEST(AutoRig, WeightsBlendNeighbouringBonesAndSumToOne) {
  const TriMesh tube = test::capped_tube(20, 6, 4.0, 0.5);
  const Rig rig = auto_rig(tube, {.joints = 4});
  ASSERT_EQ(rig.joints.size(), 4u);
  ASSERT_EQ(rig.clips.size(), 2u);
  for (std::size_t v = 0; v < tube.vertex_count(); ++v) {
    const auto begin = rig.weights.offsets[v], end = rig.weights.offsets[v + 1];
    ASSERT_GE(end - begin, 1u);
    ASSERT_LE(end - begin, 2u);
    double sum = 0.0;
    for (auto i = begin; i < end; ++i) sum += rig.weights.weight[i];
    EXPECT_NEAR(sum, 1.0, 1e-6);
  }
  // The far cap (x beyond the last slice's centre) is all on the last bone.
  const std::size_t far = tube.vertex_count() - 1;
  EXPECT_EQ(rig.weights.offsets[far + 1] - rig.weights.offsets[far], 1u);
  EXPECT_EQ(rig.weights.binding[rig.weights.offsets[far]], 3u);
  EXPECT_THROW(auto_rig(tube, {.joints = 1}), RigError);
}

std::filesystem::path temp_file(const std::string& name) {
  return std::filesystem::path(::testing::TempDir()) / ("filigree_skin_" + std::to_string(::getpid()) + "_" + name);
}

TEST(GltfSkin, WrittenRigReadsBackWithItsSkeletonWeightsAndClips) {
  const TriMesh tube = test::capped_tube(16, 8);
  const Rig rig = auto_rig(tube, {.joints = 3});
  const auto path = temp_file("roundtrip.glb");
  write_glb_rigged(tube, rig, path);
  const RiggedMesh back = read_rigged_mesh(path);
  std::filesystem::remove(path);
  ASSERT_TRUE(back.rig.has_value());
  const Rig& r = *back.rig;
  ASSERT_EQ(r.joints.size(), rig.joints.size());
  for (std::size_t j = 0; j < r.joints.size(); ++j) {
    EXPECT_EQ(r.joints[j].name, rig.joints[j].name);
    EXPECT_EQ(r.joints[j].parent, rig.joints[j].parent);
    EXPECT_LT((r.joints[j].rest.translation - rig.joints[j].rest.translation).norm(), 1e-6);
  }
  ASSERT_EQ(r.vertex_count(), tube.vertex_count());
  EXPECT_EQ(r.weights.offsets, rig.weights.offsets);
  EXPECT_EQ(r.weights.binding, rig.weights.binding);
  for (std::size_t i = 0; i < r.weights.weight.size(); ++i) EXPECT_NEAR(r.weights.weight[i], rig.weights.weight[i], 1e-6);
  ASSERT_EQ(r.clips.size(), 2u);
  EXPECT_EQ(r.clips[0].name, "bend");
  EXPECT_EQ(r.clips[1].channels[0].interpolation, ClipChannel::Interpolation::kCubicSpline);
  EXPECT_EQ(r.clips[1].channels[0].values, rig.clips[1].channels[0].values);
  // At rest the skin gives the mesh back.
  for (std::size_t i = 0; i < tube.vertex_count(); ++i) ASSERT_LT((back.mesh.positions[i] - tube.positions[i]).norm(), 1e-5);
}

// A glTF model made by hand: two skinned primitives sharing one skin whose
// root joint hangs under an "armature" node with a transform, the second
// primitive with six influences (JOINTS_1/WEIGHTS_1), and an unskinned node
// with a transform of its own.
class HandMadeGltf {
 public:
  HandMadeGltf() {
    model.asset.version = "2.0";
    model.buffers.resize(1);
    // Nodes: 0 armature (translate +10 z), 1 joint root, 2 joint child (+1 x),
    // 3 skinned mesh node (transform ignored by glTF rules), 4 static mesh (translate +5 y).
    model.nodes.resize(5);
    model.nodes[0].name = "armature";
    model.nodes[0].translation = {0, 0, 10};
    model.nodes[0].children = {1};
    model.nodes[1].name = "root";
    model.nodes[1].children = {2};
    model.nodes[2].name = "tip";
    model.nodes[2].translation = {1, 0, 0};
    model.nodes[3].mesh = 0;
    model.nodes[3].skin = 0;
    model.nodes[3].translation = {100, 100, 100};
    model.nodes[4].mesh = 1;
    model.nodes[4].translation = {0, 5, 0};
    model.scenes.push_back({});
    model.scenes[0].nodes = {0, 3, 4};
    model.defaultScene = 0;
    tinygltf::Skin skin;
    skin.joints = {1, 2};
    // Bind pose = rest pose: inverse of the joints' world transforms.
    const Mat4 root_world = translation(Vec3(0, 0, 10)), tip_world = root_world * translation(Vec3(1, 0, 0));
    std::vector<float> ibm;
    for (const Mat4& w : {root_world, tip_world}) {
      const Eigen::Matrix4f inv = w.inverse().cast<float>();
      ibm.insert(ibm.end(), inv.data(), inv.data() + 16);
    }
    skin.inverseBindMatrices = add(ibm, TINYGLTF_TYPE_MAT4, 16);
    model.skins.push_back(skin);

    tinygltf::Mesh skinned;
    skinned.primitives.push_back(triangle({0, 0, 10}, {{0, 1, 0, 0}}, {{0.5f, 0.5f, 0, 0}}));
    // Six influences over two sets: 0.1·4 + 0.3·2 = 1.
    skinned.primitives.push_back(
        triangle({2, 0, 10}, {{0, 1, 0, 1}, {0, 1, 0, 0}}, {{0.1f, 0.1f, 0.1f, 0.1f}, {0.3f, 0.3f, 0, 0}}));
    model.meshes.push_back(skinned);
    tinygltf::Mesh plain;
    plain.primitives.push_back(triangle({0, 0, 0}, {}, {}));
    model.meshes.push_back(plain);
  }

  std::string glb() {
    std::ostringstream out;
    tinygltf::TinyGLTF writer;
    writer.WriteGltfSceneToStream(&model, out, false, true);
    return out.str();
  }

  tinygltf::Model model;

 private:
  int add(const std::vector<float>& values, int type, int components) {
    return add_raw(values.data(), values.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT, type, values.size() / components);
  }
  int add_raw(const void* data, std::size_t bytes, int component, int type, std::size_t count) {
    auto& buffer = model.buffers[0].data;
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = buffer.size();
    view.byteLength = bytes;
    buffer.insert(buffer.end(), static_cast<const unsigned char*>(data), static_cast<const unsigned char*>(data) + bytes);
    model.bufferViews.push_back(view);
    tinygltf::Accessor a;
    a.bufferView = static_cast<int>(model.bufferViews.size() - 1);
    a.componentType = component;
    a.type = type;
    a.count = count;
    model.accessors.push_back(a);
    return static_cast<int>(model.accessors.size() - 1);
  }
  // A unit right triangle at `origin` (in its node's space); every vertex with
  // the same joint/weight sets.
  tinygltf::Primitive triangle(const Vec3& origin, const std::vector<std::array<std::uint16_t, 4>>& joints,
                               const std::vector<std::array<float, 4>>& weights) {
    tinygltf::Primitive p;
    std::vector<float> positions;
    for (const Vec3& c : {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)})
      for (int k = 0; k < 3; ++k) positions.push_back(static_cast<float>(origin[k] + c[k]));
    tinygltf::Accessor unused;
    p.attributes["POSITION"] = add(positions, TINYGLTF_TYPE_VEC3, 3);
    model.accessors.back().minValues = {origin.x(), origin.y(), origin.z()};
    model.accessors.back().maxValues = {origin.x() + 1, origin.y() + 1, origin.z()};
    for (std::size_t set = 0; set < joints.size(); ++set) {
      std::vector<std::uint16_t> j;
      std::vector<float> w;
      for (int v = 0; v < 3; ++v) {
        j.insert(j.end(), joints[set].begin(), joints[set].end());
        w.insert(w.end(), weights[set].begin(), weights[set].end());
      }
      p.attributes["JOINTS_" + std::to_string(set)] =
          add_raw(j.data(), j.size() * 2, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_VEC4, 3);
      p.attributes["WEIGHTS_" + std::to_string(set)] = add(w, TINYGLTF_TYPE_VEC4, 4);
    }
    p.mode = TINYGLTF_MODE_TRIANGLES;
    return p;
  }
};

TEST(GltfSkin, SeveralSkinnedPrimitivesNodeTransformsAndSixInfluences) {
  HandMadeGltf file;
  const RiggedMesh read = read_rigged_mesh_from_memory(file.glb(), "glb");
  ASSERT_TRUE(read.rig.has_value());
  const Rig& rig = *read.rig;
  ASSERT_EQ(rig.joints.size(), 2u);
  EXPECT_EQ(rig.joints[0].name, "root");
  EXPECT_EQ(rig.joints[1].parent, 0);
  // The armature's transform sits above the root joint.
  EXPECT_LT((rig.joints[0].root_parent - translation(Vec3(0, 0, 10))).norm(), 1e-12);
  ASSERT_EQ(read.mesh.vertex_count(), 9u);
  // Skinned vertices at rest are where the file put them (bind = rest): the
  // mesh node's own transform (+100) is ignored, as glTF requires.
  EXPECT_LT((read.mesh.positions[0] - Vec3(0, 0, 10)).norm(), 1e-5);
  EXPECT_LT((read.mesh.positions[3] - Vec3(2, 0, 10)).norm(), 1e-5);
  // The unskinned node keeps its transform and gets no weights.
  EXPECT_LT((read.mesh.positions[6] - Vec3(0, 5, 0)).norm(), 1e-12);
  EXPECT_EQ(rig.weights.offsets[7] - rig.weights.offsets[6], 0u);
  // Six influences on the second primitive's vertices.
  EXPECT_EQ(rig.weights.offsets[4] - rig.weights.offsets[3], 6u);

  // Turn the root 90° about z: the tip joint (and what hangs on it) swings round.
  SkeletonPose pose = SkeletonPose::rest(rig);
  pose.local[0].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
  std::vector<Vec3> out(rig.vertex_count());
  skin(rig, model_transforms(rig, pose), SkinningMethod::kLinearBlend, out);
  // Vertex 0 at (0,0,10) is on the root's axis: fixed. Vertex 1 (1,0,10) →
  // (0,1,10) for both joints (the tip joint moves with the root).
  EXPECT_LT((out[0] - Vec3(0, 0, 10)).norm(), 1e-6);
  EXPECT_LT((out[1] - Vec3(0, 1, 10)).norm(), 1e-6);
  EXPECT_LT((out[6] - Vec3(0, 5, 0)).norm(), 1e-12);

  // Turn only the tip 90° about z: the joints now disagree, so the weights
  // decide. Both primitives weigh root and tip 0.5 each (the second through
  // six influences over two sets), so a vertex lands halfway between where
  // each joint takes it. Vertex 0 (0,0,10): root keeps it, the tip takes it
  // to (1,-1,10). Vertex 3 (2,0,10): root keeps it, the tip takes it to (1,1,10).
  SkeletonPose bend = SkeletonPose::rest(rig);
  bend.local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitZ()));
  skin(rig, model_transforms(rig, bend), SkinningMethod::kLinearBlend, out);
  EXPECT_LT((out[0] - Vec3(0.5, -0.5, 10)).norm(), 1e-6);
  EXPECT_LT((out[3] - Vec3(1.5, 0.5, 10)).norm(), 1e-6);
  EXPECT_LT((out[1] - Vec3(1, 0, 10)).norm(), 1e-6);  // at the tip joint: both keep it
}

void expect_refused(HandMadeGltf& file, const std::string& fragment) {
  try {
    read_rigged_mesh_from_memory(file.glb(), "glb");
    ADD_FAILURE() << "accepted; expected an error containing '" << fragment << "'";
  } catch (const MeshIoError& e) {
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(GltfSkin, InvalidSkinsAreClearErrors) {
  {
    HandMadeGltf file;  // joint index 7 in a skin of 2
    auto& a = file.model.accessors[file.model.meshes[0].primitives[0].attributes["JOINTS_0"]];
    auto& view = file.model.bufferViews[a.bufferView];
    std::uint16_t seven = 7;
    std::memcpy(file.model.buffers[0].data.data() + view.byteOffset + 2, &seven, 2);
    expect_refused(file, "names joint 7 of a skin of 2 joints");
  }
  {
    HandMadeGltf file;  // weights summing to 0.5
    auto& a = file.model.accessors[file.model.meshes[0].primitives[0].attributes["WEIGHTS_0"]];
    auto& view = file.model.bufferViews[a.bufferView];
    const float quarter = 0.25f;
    for (int k = 0; k < 2; ++k) std::memcpy(file.model.buffers[0].data.data() + view.byteOffset + 4 * k, &quarter, 4);
    expect_refused(file, "not 1");
  }
  {
    HandMadeGltf file;  // the skin names a node that does not exist
    file.model.skins[0].joints[1] = 42;
    expect_refused(file, "references node 42, which does not exist");
  }
  {
    HandMadeGltf file;  // a NaN inverse bind matrix
    auto& a = file.model.accessors[file.model.skins[0].inverseBindMatrices];
    auto& view = file.model.bufferViews[a.bufferView];
    const float nan = std::nanf("");
    std::memcpy(file.model.buffers[0].data.data() + view.byteOffset, &nan, 4);
    expect_refused(file, "not finite");
  }
  {
    HandMadeGltf file;  // a skinned primitive without weights
    file.model.meshes[0].primitives[0].attributes.erase("WEIGHTS_0");
    expect_refused(file, "one of the pair is missing");
  }
}

TEST(GltfSkin, MeshesWithoutSkinsHaveNoRig) {
  const TriMesh tube = test::capped_tube(6, 6);
  const auto path = temp_file("plain.glb");
  write_glb(tube, path);
  EXPECT_FALSE(read_rigged_mesh(path).rig.has_value());
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace filigree
