#include "server/session.h"
// Session's skeletal poses: joint transforms and clip samples, skinned onto
// the base mesh and merged as a pose of their driver.

#include <string>
#include <utility>

#include "skinning/animation_clip.h"
#include "skinning/rig_file.h"
#include "skinning/skinning.h"

namespace filigree::server {

void Session::submit_joints(const PoseOrigin& origin, const v1::JointPose& joints) {
  if (!rig_)
    throw PoseError("session " + record_.id + " has no skeleton (its upload was not a skinned glTF): pose it by positions");
  const bool model = joints.space() == v1::JointPose::SPACE_MODEL_MATRIX;
  if (!model && joints.space() != v1::JointPose::SPACE_LOCAL_TRS)
    throw PoseError("joint pose space " + std::to_string(joints.space()) + " is unknown");
  const std::size_t per = model ? 16 : 10, n = rig_->joints.size();
  const std::size_t count = joints.joint_indices().empty() ? n : static_cast<std::size_t>(joints.joint_indices_size());
  if (static_cast<std::size_t>(joints.values_size()) != per * count)
    throw PoseError("joint pose has " + std::to_string(joints.values_size()) + " values for " + std::to_string(count) +
                    " joints; expected " + std::to_string(per * count) + " (" + std::to_string(per) + " per joint)");
  std::vector<bool> seen(n, false);
  for (int i = 0; i < joints.joint_indices_size(); ++i) {
    const std::uint32_t j = joints.joint_indices(i);
    if (j >= n)
      throw PoseError("joint index " + std::to_string(j) + " at position " + std::to_string(i) +
                      " is out of range: the skeleton has " + std::to_string(n) + " joints");
    if (seen[j]) throw PoseError("joint " + std::to_string(j) + " is named twice in one pose");
    seen[j] = true;
  }
  for (int i = 0; i < joints.values_size(); ++i)
    if (!std::isfinite(joints.values(i))) {
      const std::size_t entry = static_cast<std::size_t>(i) / per;
      const std::size_t joint = joints.joint_indices().empty() ? entry : joints.joint_indices(static_cast<int>(entry));
      throw PoseError("joint pose value " + std::to_string(i) + " (joint " + std::to_string(joint) + ") is not finite (NaN or Inf)");
    }
  // Parse all joints before changing the state: a bad one changes nothing.
  std::vector<JointTransform> locals(model ? 0 : count);
  std::vector<Mat4> matrices(model ? count : 0);
  for (std::size_t k = 0; k < count; ++k) {
    const float* v = joints.values().data() + per * k;
    // Errors name the joint (its index in the skeleton), not the entry.
    const std::size_t joint = joints.joint_indices().empty() ? k : joints.joint_indices(static_cast<int>(k));
    if (model) {
      Mat4 m;
      for (int c = 0; c < 16; ++c) m(c % 4, c / 4) = v[c];  // column-major
      if (std::abs(m(3, 0)) > 1e-6 || std::abs(m(3, 1)) > 1e-6 || std::abs(m(3, 2)) > 1e-6 || std::abs(m(3, 3) - 1.0) > 1e-6)
        throw PoseError("joint " + std::to_string(joint) + "'s matrix is not affine (its last row must be 0 0 0 1)");
      matrices[k] = m;
    } else {
      JointTransform& t = locals[k];
      t.translation = Vec3(v[0], v[1], v[2]);
      const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);  // given x y z w
      if (!(q.norm() > 1e-6)) throw PoseError("joint " + std::to_string(joint) + " has a zero rotation quaternion");
      t.rotation = q.normalized();
      t.scale = Vec3(v[7], v[8], v[9]);
    }
  }
  std::lock_guard lock(skeleton_mutex_);
  const SkeletonPose before = *joint_pose_;
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t j = joints.joint_indices().empty() ? k : joints.joint_indices(static_cast<int>(k));
    if (model) {
      joint_pose_->model[j] = matrices[k];
    } else {
      joint_pose_->local[j] = locals[k];
      joint_pose_->model[j].reset();
    }
  }
  try {
    submit_skinned_locked(origin);
  } catch (const PoseError&) {
    *joint_pose_ = before;  // a refused pose changes nothing
    throw;
  }
}

const AnimationClip* Session::clip(const std::string& name) const { return rig_ ? rig_->clip(name) : nullptr; }

void Session::submit_clip_sample(const PoseOrigin& origin, const AnimationClip& clip, double seconds) {
  std::lock_guard lock(skeleton_mutex_);
  for (const ClipChannel& c : clip.channels) {
    joint_pose_->local[c.joint] = rig_->joints[c.joint].rest;
    joint_pose_->model[c.joint].reset();
  }
  sample_clip(clip, seconds, joint_pose_->local);
  submit_skinned_locked(origin);
}

void Session::submit_skinned_locked(const PoseOrigin& origin) {
  const std::size_t m = rig_->vertex_count();
  std::vector<Vec3>& skinned = skinned_positions_;  // reused pose to pose (skeleton_mutex_ held)
  skinned.resize(m);
  try {
    const std::vector<Mat4> model = model_transforms(*rig_, *joint_pose_);
    skin(*rig_, model,
         record_.options.skinning() == v1::SKINNING_DUAL_QUATERNION ? SkinningMethod::kDualQuaternion
                                                                    : SkinningMethod::kLinearBlend,
         skinned);
  } catch (const RigError& e) {
    throw PoseError(std::string("the joint pose cannot skin the base: ") + e.what());
  }
  skinned_.resize(3 * m);
  for (std::size_t i = 0; i < m; ++i)
    for (int k = 0; k < 3; ++k) {
      const double c = skinned[i][k];
      if (!std::isfinite(c)) throw PoseError("the joint pose moves base vertex " + std::to_string(i) + " to a non-finite place");
      check_reach(c, "the joint pose's base vertex", i);
      skinned_[3 * i + k] = static_cast<float>(c);
    }
  merge(origin, {}, skinned_, /*skinned=*/true);
}

}  // namespace filigree::server
