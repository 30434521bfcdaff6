#pragma once
// Skeletal poses and skinning: joint transforms → positions of a rigged mesh
// (issue 13). Used on the base mesh: the server skins it, then the usual
// pipeline adds the detail.

#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "skinning/rig.h"

namespace filigree {

enum class SkinningMethod : std::uint8_t {
  kLinearBlend,     // Σ w·M·B·x: glTF's reference skinning
  kDualQuaternion,  // Kavan et al. 2007: blends rigid parts, no volume collapse at twists
};

// A skeleton's state: per joint a local transform, or a model transform given
// directly (which then wins, and its children follow it).
struct SkeletonPose {
  std::vector<JointTransform> local;
  std::vector<std::optional<Mat4>> model;

  // Every joint at its rest transform.
  static SkeletonPose rest(const Rig& rig);
};

// Model transform of every joint: local transforms composed from the roots
// down (Joint::root_parent above a root), unless the joint's model transform
// is given. Precondition: pose sizes equal rig.joints.size().
std::vector<Mat4> model_transforms(const Rig& rig, const SkeletonPose& pose);

// Positions of the rig's vertices for joint model transforms `joint_model`
// (one per joint): each binding's skinning matrix is M_joint · B, then
// blended per vertex by `method`. Vertices without influences keep their bind
// position. Dual quaternions take the rigid part of each skinning matrix
// (scale is ignored, as in Kavan et al.). Throws RigError if out.size() or
// joint_model.size() disagree with the rig, or a result is not finite.
void skin(const Rig& rig, std::span<const Mat4> joint_model, SkinningMethod method, std::span<Vec3> out);

}  // namespace filigree
