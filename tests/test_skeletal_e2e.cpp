// Skeletal poses and clips through filigree-server (issue 13), with the C++
// client library: a limb made by the test, rigged, uploaded as a skinned GLB,
// then posed by joints. Expected base poses come from the test's own plain
// linear blend skinning, not from the server's code.

#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <sstream>

#include <gtest/gtest.h>
#include <tiny_gltf.h>

#include "filigree/client.h"
#include "mesh/gltf_io.h"
#include "skinning/animation_clip.h"
#include "skinning/auto_rig.h"
#include "support/server_process.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

class SkeletalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string name = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    dir_ = std::filesystem::path(::testing::TempDir()) / ("filigree_skel_" + std::to_string(::getpid()) + "_" + name);
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    server_ = std::make_unique<test::ServerProcess>(FILIGREE_SERVER_BINARY,
                                                    std::vector<std::string>{"--data-dir", (dir_ / "data").string()});
    client_ = std::make_unique<Client>(server_->address());
    limb_ = test::capped_tube(24, 10, 4.0, 0.5);
    rig_ = auto_rig(limb_, {.joints = 3, .bend_degrees = 70.0});
    write_glb_rigged(limb_, rig_, dir_ / "limb.glb");
    glb_ = test::file_bytes((dir_ / "limb.glb").string());
  }
  void TearDown() override {
    client_.reset();
    server_.reset();
    std::filesystem::remove_all(dir_);
  }

  SessionHandle upload(const std::string& bytes, const std::string& format = "glb",
                       v1::SkinningMethod skinning = v1::SKINNING_LINEAR_BLEND) {
    v1::SessionOptions o;
    o.set_base_vertices(60);
    o.set_skinning(skinning);
    return client_->create_session(bytes, format, o, "test");
  }

  // The test's LBS of the limb's vertex `v` for local joint transforms `local`.
  Vec3 plain_lbs(std::size_t v, const std::vector<JointTransform>& local) const {
    std::vector<Mat4> world(rig_.joints.size());
    for (std::size_t j = 0; j < world.size(); ++j) {
      Mat4 m = Mat4::Identity();
      m.topLeftCorner<3, 3>() = local[j].rotation.toRotationMatrix() * local[j].scale.asDiagonal();
      m.topRightCorner<3, 1>() = local[j].translation;
      world[j] = rig_.joints[j].parent < 0 ? m : Mat4(world[rig_.joints[j].parent] * m);
    }
    const Eigen::Vector4d x(limb_.positions[v].x(), limb_.positions[v].y(), limb_.positions[v].z(), 1.0);
    Eigen::Vector4d p = Eigen::Vector4d::Zero();
    for (auto i = rig_.weights.offsets[v]; i < rig_.weights.offsets[v + 1]; ++i) {
      const Binding& b = rig_.bindings[rig_.weights.binding[i]];
      p += double{rig_.weights.weight[i]} * (world[b.joint] * b.inverse_bind * x);
    }
    return p.head<3>();
  }

  // The base pose (3·m floats) the test's LBS gives for `local`.
  std::vector<float> base_pose(const SessionMesh& mesh, const std::vector<JointTransform>& local) const {
    std::vector<float> out;
    for (const std::uint32_t original : mesh.base_original_ids) {
      const std::uint32_t uploaded = mesh.uploaded_ids.empty() ? original : mesh.uploaded_ids[original];
      const Vec3 p = plain_lbs(uploaded, local);
      for (int k = 0; k < 3; ++k) out.push_back(static_cast<float>(p[k]));
    }
    return out;
  }

  static std::vector<float> trs_values(const std::vector<JointTransform>& local) {
    std::vector<float> v;
    for (const JointTransform& t : local)
      for (const double c : {t.translation.x(), t.translation.y(), t.translation.z(), t.rotation.x(), t.rotation.y(),
                             t.rotation.z(), t.rotation.w(), t.scale.x(), t.scale.y(), t.scale.z()})
        v.push_back(static_cast<float>(c));
    return v;
  }

  std::vector<JointTransform> rest_locals() const {
    std::vector<JointTransform> out;
    for (const Joint& j : rig_.joints) out.push_back(j.rest);
    return out;
  }

  // Drives one pose on a new stream and returns the frame that includes it.
  DecodedFrame drive_one(const SessionHandle& s, const std::function<bool(Driver&)>& send) {
    auto driver = client_->drive(s.session_id, s.editor_token, "test");
    EXPECT_TRUE(send(*driver));
    FrameDecoder decoder(s.mesh.rest_positions);
    while (auto frame = driver->read()) {
      DecodedFrame d = decoder.decode(*frame);
      if (d.pose_id == 1) {
        driver->cancel();
        driver->finish();
        return d;
      }
    }
    ADD_FAILURE() << "the stream ended before the frame of pose 1: " << driver->finish().error_message();
    return {};
  }

  // Sends `pose` raw (the client library checks sizes itself) and returns how the stream ended.
  grpc::Status refused(const SessionHandle& s, const v1::JointPose& pose) {
    grpc::ClientContext context;
    set_session_metadata(context, s.session_id, s.editor_token, Routing::kLoadBalanced);
    auto stream = client_->stub().Drive(&context);
    v1::DriveRequest request;
    request.set_session_id(s.session_id);
    request.set_pose_id(1);
    *request.mutable_joints() = pose;
    stream->Write(request);
    stream->WritesDone();
    // The pose is refused as that pose (Frame.refused): the stream goes on and
    // ends OK on the half-close.
    v1::Frame frame;
    grpc::Status refusal;
    while (stream->Read(&frame))
      if (frame.has_refused())
        refusal = grpc::Status(static_cast<grpc::StatusCode>(frame.refused().code()), frame.refused().message());
    const grpc::Status ended = stream->Finish();
    EXPECT_TRUE(ended.ok()) << ended.error_message();
    return refusal;
  }

  std::filesystem::path dir_;
  std::unique_ptr<test::ServerProcess> server_;
  std::unique_ptr<Client> client_;
  TriMesh limb_;
  Rig rig_;
  std::string glb_;
};

double max_distance(const std::vector<float>& a, const std::vector<float>& b) {
  double d = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) d = std::max(d, std::abs(double{a[i]} - b[i]));
  return d;
}

TEST_F(SkeletalTest, SessionInfoTellsTheSkeletonAndItsClips) {
  const SessionHandle s = upload(glb_);
  const v1::Skeleton& k = s.mesh.skeleton;
  ASSERT_EQ(k.joints_size(), 3);
  EXPECT_EQ(k.joints(0).name(), "bone0");
  EXPECT_EQ(k.joints(2).parent(), 1);
  ASSERT_EQ(k.joints(1).rest_size(), 10);
  ASSERT_EQ(k.clips_size(), 2);
  EXPECT_EQ(k.clips(0).name(), "bend");
  EXPECT_NEAR(k.clips(0).duration_seconds(), 2.0, 1e-6);
  // A joined session says the same (the rig is in the session record).
  EXPECT_EQ(client_->join(s.session_id, s.viewer_token).skeleton.SerializeAsString(), k.SerializeAsString());
}

TEST_F(SkeletalTest, RestJointsGiveTheRestMesh) {
  const SessionHandle s = upload(glb_);
  // Bent first, so that rest joints must bring the mesh back (not just leave it).
  std::vector<JointTransform> bent = rest_locals();
  bent[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.6, Vec3::UnitZ()));
  const std::vector<float> bent_values = trs_values(bent);
  const DecodedFrame b =
      drive_one(s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, bent_values); });
  EXPECT_GT(max_distance(b.positions, s.mesh.rest_positions), 100.0 * (double{b.max_error} + 1e-6));
  const std::vector<float> values = trs_values(rest_locals());
  const DecodedFrame f = drive_one(s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, values); });
  ASSERT_EQ(f.positions.size(), s.mesh.rest_positions.size());
  EXPECT_LE(max_distance(f.positions, s.mesh.rest_positions), double{f.max_error} + 1e-6);
}

TEST_F(SkeletalTest, JointPoseGivesTheFrameOfThePlainLbsBasePose) {
  std::vector<JointTransform> local = rest_locals();
  local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.6, Vec3::UnitZ()));
  local[2].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(-0.4, Vec3::UnitY()));
  const SessionHandle by_joints = upload(glb_);
  const SessionHandle by_positions = upload(glb_);
  const std::vector<float> values = trs_values(local);
  const DecodedFrame a =
      drive_one(by_joints, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, values); });
  const std::vector<float> pose = base_pose(by_positions.mesh, local);
  const DecodedFrame b = drive_one(by_positions, [&](Driver& d) { return d.send(1, pose); });
  // The merged pose is the test's LBS, and the frames agree within quantization.
  const v1::SessionState state = client_->state(by_joints.session_id, by_joints.viewer_token);
  EXPECT_LE(max_distance({state.pose().begin(), state.pose().end()}, pose), 1e-5);
  EXPECT_LE(max_distance(a.positions, b.positions), double{a.max_error} + b.max_error + 1e-5);
  // And it moved: the tip is far from rest.
  EXPECT_GT(max_distance(a.positions, by_joints.mesh.rest_positions), 0.5);

  // Model-space matrices for the same pose give the same merged pose.
  const SessionHandle by_matrices = upload(glb_);
  std::vector<float> matrices;
  Mat4 parent = Mat4::Identity();
  for (std::size_t j = 0; j < local.size(); ++j) {
    Mat4 m = Mat4::Identity();
    m.topLeftCorner<3, 3>() = local[j].rotation.toRotationMatrix();
    m.topRightCorner<3, 1>() = local[j].translation;
    parent = j == 0 ? m : Mat4(parent * m);
    for (int c = 0; c < 16; ++c) matrices.push_back(static_cast<float>(parent(c % 4, c / 4)));
  }
  drive_one(by_matrices, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_MODEL_MATRIX, {}, matrices); });
  const v1::SessionState m = client_->state(by_matrices.session_id, by_matrices.viewer_token);
  EXPECT_LE(max_distance({m.pose().begin(), m.pose().end()}, pose), 1e-5);
}

TEST_F(SkeletalTest, DualQuaternionSkinningIsTheSessionsOption) {
  // A twist of 150° about the chain's axis: linear blending pulls the blended
  // vertices towards the axis, dual quaternions keep them at the tube's radius.
  std::vector<JointTransform> local = rest_locals();
  local[2].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(150.0 * M_PI / 180.0, Vec3::UnitX()));
  const std::vector<float> values = trs_values(local);
  const SessionHandle lbs = upload(glb_);
  const SessionHandle dq = upload(glb_, "glb", v1::SKINNING_DUAL_QUATERNION);
  for (const SessionHandle* s : {&lbs, &dq})
    drive_one(*s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, values); });
  // The smallest distance of a base vertex from the chain's axis (y = z = 0).
  auto thinnest = [&](const SessionHandle& s) {
    const v1::SessionState state = client_->state(s.session_id, s.viewer_token);
    double r = 1e30;
    for (int i = 0; i + 2 < state.pose_size(); i += 3) {
      const double x = state.pose(i);
      if (x > 0.2 && x < 3.8) r = std::min(r, std::hypot(double{state.pose(i + 1)}, double{state.pose(i + 2)}));
    }
    return r;
  };
  EXPECT_LT(thinnest(lbs), 0.4);         // collapsed (the tube's radius is 0.5)
  EXPECT_GT(thinnest(dq), 0.5 - 1e-3);   // kept
  const v1::SessionState state = client_->state(lbs.session_id, lbs.viewer_token);
  EXPECT_LE(max_distance({state.pose().begin(), state.pose().end()}, base_pose(lbs.mesh, local)), 1e-5);
}

TEST_F(SkeletalTest, PartialSkeletalPosesMerge) {
  std::vector<JointTransform> local = rest_locals();
  local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Vec3::UnitZ()));
  local[2].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Vec3::UnitY()));
  const SessionHandle s = upload(glb_);
  const std::vector<float> all = trs_values(local);
  const std::vector<std::uint32_t> one = {1}, two = {2};
  const std::vector<float> first(all.begin() + 10, all.begin() + 20), second(all.begin() + 20, all.end());
  {
    auto a = client_->drive(s.session_id, s.editor_token, "alice");
    ASSERT_TRUE(a->send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, one, first));
    ASSERT_TRUE(a->writes_done());
    ASSERT_TRUE(a->finish().ok());
  }
  drive_one(s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, two, second); });
  const v1::SessionState state = client_->state(s.session_id, s.viewer_token);
  EXPECT_LE(max_distance({state.pose().begin(), state.pose().end()}, base_pose(s.mesh, local)), 1e-5);
}

TEST_F(SkeletalTest, HandlesStayOnTopOfTheSkinnedBase) {
  const SessionHandle s = upload(glb_);
  // A handle on the far cap's centre (the last uploaded vertex), pulled sideways from rest.
  const std::uint32_t tip_uploaded = static_cast<std::uint32_t>(limb_.vertex_count() - 1);
  std::uint32_t tip = tip_uploaded;
  for (std::uint32_t i = 0; i < s.mesh.uploaded_ids.size(); ++i)
    if (s.mesh.uploaded_ids[i] == tip_uploaded) tip = i;
  const Vec3 target = limb_.positions[tip_uploaded] + Vec3(0, 0.5, 0);
  {
    grpc::ClientContext context;
    set_session_metadata(context, s.session_id, s.editor_token, Routing::kLoadBalanced);
    v1::SetHandlesRequest request;
    request.set_session_id(s.session_id);
    request.set_client_name("sculptor");
    v1::Handle& h = *request.add_handles();
    h.set_vertex(tip);
    h.set_x(static_cast<float>(target.x()));
    h.set_y(static_cast<float>(target.y()));
    h.set_z(static_cast<float>(target.z()));
    v1::SetHandlesResponse response;
    ASSERT_TRUE(client_->stub().SetHandles(&context, request, &response).ok());
  }
  // Then the skeleton bends the limb down: without the handle the tip would be far from its target.
  std::vector<JointTransform> local = rest_locals();
  local[1].rotation = Eigen::Quaterniond(Eigen::AngleAxisd(-0.6, Vec3::UnitZ()));
  const Vec3 lbs_tip = plain_lbs(tip_uploaded, local);
  ASSERT_GT((lbs_tip - target).norm(), 0.8);
  const std::vector<float> values = trs_values(local);
  const DecodedFrame f = drive_one(s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, values); });
  const Vec3 shown(f.positions[3 * tip], f.positions[3 * tip + 1], f.positions[3 * tip + 2]);
  EXPECT_LT((shown - target).norm(), 0.2) << "the handle was not solved on top of the skinned base";
  // With a single handle, as-rigid-as-possible moves the skinned limb as a
  // whole: its bent shape is kept (the root end moves as the tip does).
  std::uint32_t root = 0;
  for (std::uint32_t i = 0; i < s.mesh.uploaded_ids.size(); ++i)
    if (s.mesh.uploaded_ids[i] == 0) root = i;
  const Vec3 root_moved = Vec3(f.positions[3 * root], f.positions[3 * root + 1], f.positions[3 * root + 2]) - plain_lbs(0, local);
  EXPECT_LT((root_moved - (shown - lbs_tip)).norm(), 0.1);
}

TEST_F(SkeletalTest, BadSkinsAreInvalidArgumentsAtUpload) {
  // The limb's file edited with tinygltf: each defect alone, uploaded through the service.
  auto edited = [&](const std::function<void(tinygltf::Model&)>& edit) {
    tinygltf::TinyGLTF io;
    tinygltf::Model model;
    std::string error, warning;
    EXPECT_TRUE(io.LoadBinaryFromMemory(&model, &error, &warning, reinterpret_cast<const unsigned char*>(glb_.data()),
                                        static_cast<unsigned>(glb_.size())));
    edit(model);
    std::ostringstream out;
    io.WriteGltfSceneToStream(&model, out, false, true);
    return out.str();
  };
  auto float_of = [](tinygltf::Model& m, int accessor, std::size_t index) -> float* {
    const tinygltf::Accessor& a = m.accessors[accessor];
    const tinygltf::BufferView& v = m.bufferViews[a.bufferView];
    return reinterpret_cast<float*>(m.buffers[v.buffer].data.data() + v.byteOffset + a.byteOffset) + index;
  };
  const std::vector<std::pair<std::string, std::function<void(tinygltf::Model&)>>> cases = {
      {"references node 42, which does not exist", [](tinygltf::Model& m) { m.skins[0].joints[1] = 42; }},
      {"not 1", [&](tinygltf::Model& m) { *float_of(m, m.meshes[0].primitives[0].attributes["WEIGHTS_0"], 0) += 0.5f; }},
      {"not finite", [&](tinygltf::Model& m) { *float_of(m, m.skins[0].inverseBindMatrices, 5) = std::nanf(""); }},
      {"names joint 9 of a skin of 3 joints", [&](tinygltf::Model& m) {
         const tinygltf::Accessor& a = m.accessors[m.meshes[0].primitives[0].attributes["JOINTS_0"]];
         const tinygltf::BufferView& v = m.bufferViews[a.bufferView];
         std::uint16_t nine = 9;
         std::memcpy(m.buffers[v.buffer].data.data() + v.byteOffset + a.byteOffset, &nine, 2);
       }},
  };
  for (const auto& [fragment, edit] : cases) {
    try {
      upload(edited(edit));
      ADD_FAILURE() << "accepted; expected an error with '" << fragment << "'";
    } catch (const ClientError& e) {
      EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT) << e.what();
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  }
  // The server is unharmed: a good upload still works.
  EXPECT_EQ(upload(glb_).mesh.skeleton.joints_size(), 3);
}

TEST_F(SkeletalTest, BadJointPosesAreInvalidArgumentsAndChangeNothing) {
  const SessionHandle s = upload(glb_);
  const std::vector<float> rest = trs_values(rest_locals());
  auto expect_invalid = [&](v1::JointPose pose, const std::string& fragment) {
    const grpc::Status status = refused(s, pose);
    EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << fragment;
    EXPECT_NE(status.error_message().find(fragment), std::string::npos) << status.error_message();
  };
  v1::JointPose nan;
  nan.mutable_values()->Assign(rest.begin(), rest.end());
  nan.set_values(4, std::nanf(""));
  expect_invalid(nan, "not finite");
  v1::JointPose out_of_range;
  out_of_range.add_joint_indices(7);
  out_of_range.mutable_values()->Assign(rest.begin(), rest.begin() + 10);
  expect_invalid(out_of_range, "out of range: the skeleton has 3 joints");
  v1::JointPose short_pose;
  short_pose.mutable_values()->Assign(rest.begin(), rest.begin() + 25);
  expect_invalid(short_pose, "expected 30");
  v1::JointPose zero_rotation;
  zero_rotation.add_joint_indices(1);
  zero_rotation.mutable_values()->Assign(rest.begin(), rest.begin() + 10);
  for (int k = 3; k < 7; ++k) zero_rotation.set_values(k, 0.0f);
  expect_invalid(zero_rotation, "zero rotation");
  v1::JointPose twice;
  twice.add_joint_indices(1);
  twice.add_joint_indices(1);
  twice.mutable_values()->Assign(rest.begin(), rest.begin() + 20);
  expect_invalid(twice, "named twice");
  // Valid values that cannot skin: scales of 3e38 compose to 9e76, far past
  // the mesh's reach (and float's range). Refused after the joints were set,
  // so they must be undone.
  std::vector<JointTransform> huge = rest_locals();
  huge[0].scale = huge[1].scale = Vec3::Constant(3e38);
  const std::vector<float> huge_values = trs_values(huge);
  v1::JointPose overflow;
  overflow.mutable_values()->Assign(huge_values.begin(), huge_values.end());
  expect_invalid(overflow, "beyond this mesh's reach");
  // Nothing changed: the session is still at rest, and still takes good poses.
  const v1::SessionState state = client_->state(s.session_id, s.viewer_token);
  EXPECT_EQ(state.version(), 0u);
  EXPECT_LE(max_distance({state.pose().begin(), state.pose().end()}, s.mesh.base_positions), 0.0);
  // A pose of the last joint alone skins with the others as they were before
  // the refused pose (at rest), not with its scales (which would fail again).
  const std::vector<float> last_joint(rest.begin() + 20, rest.end());
  const std::vector<std::uint32_t> joint_2{2};
  const DecodedFrame f =
      drive_one(s, [&](Driver& d) { return d.send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, joint_2, last_joint); });
  EXPECT_LE(max_distance(f.positions, s.mesh.rest_positions), double{f.max_error} + 1e-6);
}

TEST_F(SkeletalTest, SessionsWithoutASkeletonRefuseJointsAndClips) {
  TriMesh plain = limb_;
  write_glb(plain, dir_ / "plain.glb");
  const SessionHandle s = upload(test::file_bytes((dir_ / "plain.glb").string()));
  EXPECT_EQ(s.mesh.skeleton.joints_size(), 0);
  v1::JointPose pose;
  pose.mutable_values()->Resize(10, 0.0f);
  const grpc::Status status = refused(s, pose);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(status.error_message().find("no skeleton"), std::string::npos) << status.error_message();
  // Through the library's Driver: read() goes past the refusal, which
  // last_refusal() tells, and the next pose is answered on the same stream.
  auto driver = client_->drive(s.session_id, s.editor_token, "refused");
  const std::vector<float> values(10, 0.5f);
  ASSERT_TRUE(driver->send_joints(1, v1::JointPose::SPACE_LOCAL_TRS, {}, values));
  ASSERT_TRUE(driver->send(2, s.mesh.base_positions));
  std::optional<v1::Frame> frame;
  while ((frame = driver->read()) && frame->pose_id() < 2) {
  }
  ASSERT_TRUE(frame) << driver->finish().error_message();
  const auto refusal = driver->last_refusal();
  ASSERT_TRUE(refusal);
  EXPECT_EQ(refusal->pose_id, 1u);
  EXPECT_NE(refusal->message.find("no skeleton"), std::string::npos) << refusal->message;
  driver->cancel();
  auto clip = client_->play_clip(s.session_id, s.editor_token, "bend");
  EXPECT_EQ(clip->finish().error_code(), grpc::StatusCode::FAILED_PRECONDITION);
}

TEST_F(SkeletalTest, PlayClipStreamsTheClipAndEndsAfterItsLastSample) {
  const SessionHandle s = upload(glb_);
  auto unknown = client_->play_clip(s.session_id, s.editor_token, "nope");
  EXPECT_EQ(unknown->finish().error_code(), grpc::StatusCode::NOT_FOUND);
  auto viewer = client_->play_clip(s.session_id, s.viewer_token, "bend");
  EXPECT_EQ(viewer->finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);

  ClipPlayback fast;
  fast.speed = 8.0;  // a 2 s clip in 0.25 s
  auto stream = client_->play_clip(s.session_id, s.editor_token, "bend", fast);
  FrameDecoder decoder(s.mesh.rest_positions);
  std::uint64_t last_version = 0, last_sample = 0;
  std::size_t frames = 0;
  double furthest = 0.0;
  DecodedFrame last;
  while (auto frame = stream->read()) {
    last = decoder.decode(*frame);
    // (A keyframe the stream had not sent may come before a frame with an older version.)
    if (frames > 0 && last.keyframe && last.version < last_version) continue;
    if (frames > 0) {
      EXPECT_GT(last.version, last_version);
    }
    EXPECT_GE(last.pose_id, last_sample);
    last_version = last.version;
    last_sample = last.pose_id;
    furthest = std::max(furthest, max_distance(last.positions, s.mesh.rest_positions));
    ++frames;
  }
  ASSERT_TRUE(stream->finish().ok());
  EXPECT_GE(frames, 2u);
  EXPECT_GT(furthest, 0.3);  // it bent
  // The last sample is at the clip's end: the bend is back at rest (sin 2π = 0).
  std::vector<JointTransform> local = rest_locals();
  sample_clip(*rig_.clip("bend"), rig_.clip("bend")->duration(), local);
  const v1::SessionState state = client_->state(s.session_id, s.viewer_token);
  EXPECT_LE(max_distance({state.pose().begin(), state.pose().end()}, base_pose(s.mesh, local)), 1e-5);
  EXPECT_LE(max_distance(last.positions, s.mesh.rest_positions), double{last.max_error} + 1e-4);
}

// ClipPlayback's start time and sample rate reach the server, and each frame
// says which clip time it shows (Frame.clip_seconds, copied into
// DecodedFrame). The server takes sample k (the frames' pose_id) no sooner
// than 1/max_rate s of clip time after sample k − 1, so its clip time is at
// least start_seconds + (k − 1)/max_rate; the last sample is at the clip's
// duration.
TEST_F(SkeletalTest, PlayClipFromAStartTimeAtMostMaxRateSaysWhichClipTimeEachFrameShows) {
  const SessionHandle s = upload(glb_);
  double duration = -1.0;
  for (const v1::Skeleton::Clip& c : s.mesh.skeleton.clips())
    if (c.name() == "bend") duration = c.duration_seconds();
  ASSERT_GT(duration, 1.0);

  ClipPlayback playback;  // speed 1
  playback.start_seconds = duration - 1.0;  // the clip's last second
  playback.max_rate = 5.0;
  const double spacing = 1.0 / playback.max_rate;  // clip seconds from one sample to the next, at least
  auto stream = client_->play_clip(s.session_id, s.editor_token, "bend", playback);
  FrameDecoder decoder(s.mesh.rest_positions);
  std::uint64_t last_version = 0, samples = 0;
  std::size_t frames = 0;
  double shown = 0.0;
  while (auto frame = stream->read()) {
    const DecodedFrame f = decoder.decode(*frame);
    // (A keyframe the stream had not sent may come before a frame with an older version.)
    if (frames > 0 && f.keyframe && f.version < last_version) continue;
    last_version = f.version;
    ++frames;
    if (f.pose_id == 0) {  // the session's frame from before the first sample
      EXPECT_EQ(f.clip_seconds, 0.0) << "version " << f.version;
      continue;
    }
    EXPECT_GE(f.pose_id, samples);
    EXPECT_GE(f.clip_seconds, shown) << "sample " << f.pose_id;  // never back in a clip that does not loop
    EXPECT_GE(f.clip_seconds, playback.start_seconds + double(f.pose_id - 1) * spacing - 1e-9) << "sample " << f.pose_id;
    EXPECT_LE(f.clip_seconds, duration) << "sample " << f.pose_id;
    samples = f.pose_id;
    shown = f.clip_seconds;
  }
  ASSERT_TRUE(stream->finish().ok());
  EXPECT_DOUBLE_EQ(shown, duration);  // the last frame shows the clip's end
  // Samples 1…K−1 lie before the duration (the first at or past it is the
  // last, K), each at least `spacing` after the one before:
  // (K − 2)·spacing < duration − start_seconds.
  const auto most = static_cast<std::uint64_t>(std::floor((duration - playback.start_seconds) / spacing)) + 2;
  EXPECT_GE(samples, 2u);
  EXPECT_LE(samples, most);
}

}  // namespace
}  // namespace filigree
