#include "skinning/skinning.h"

#include <string>

namespace filigree {
namespace {

// A unit dual quaternion (real part r, dual part d) of the rigid part of `m`.
struct DualQuaternion {
  Eigen::Quaterniond r, d;
};

DualQuaternion rigid_dual_quaternion(const Mat4& m) {
  // Polar decomposition drops scale and shear: the nearest rotation.
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(m.topLeftCorner<3, 3>(), Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d rotation = svd.matrixU() * svd.matrixV().transpose();
  if (rotation.determinant() < 0.0) {
    Eigen::Matrix3d u = svd.matrixU();
    u.col(2) *= -1.0;
    rotation = u * svd.matrixV().transpose();
  }
  const Eigen::Quaterniond r(rotation);
  const Vec3 t = m.topRightCorner<3, 1>();
  // d = ½ · (0, t) · r
  const Eigen::Quaterniond d = Eigen::Quaterniond(0.0, 0.5 * t.x(), 0.5 * t.y(), 0.5 * t.z()) * r;
  return {r, d};
}

}  // namespace

SkeletonPose SkeletonPose::rest(const Rig& rig) {
  SkeletonPose pose;
  pose.local.reserve(rig.joints.size());
  for (const Joint& j : rig.joints) pose.local.push_back(j.rest);
  pose.model.assign(rig.joints.size(), std::nullopt);
  return pose;
}

std::vector<Mat4> model_transforms(const Rig& rig, const SkeletonPose& pose) {
  const std::size_t n = rig.joints.size();
  if (pose.local.size() != n || pose.model.size() != n)
    throw RigError("skeleton pose has " + std::to_string(pose.local.size()) + " joints, the rig " + std::to_string(n));
  std::vector<Mat4> model(n);
  for (std::size_t j = 0; j < n; ++j) {
    if (pose.model[j]) {
      model[j] = *pose.model[j];
      continue;
    }
    const Joint& joint = rig.joints[j];
    // validate_rig guarantees parents come first, so model[parent] is ready.
    const Mat4& above = joint.parent < 0 ? joint.root_parent : model[static_cast<std::size_t>(joint.parent)];
    model[j] = above * pose.local[j].matrix();
  }
  return model;
}

void skin(const Rig& rig, std::span<const Mat4> joint_model, SkinningMethod method, std::span<Vec3> out) {
  if (joint_model.size() != rig.joints.size())
    throw RigError("skinning: " + std::to_string(joint_model.size()) + " joint transforms for " +
                   std::to_string(rig.joints.size()) + " joints");
  if (out.size() != rig.vertex_count())
    throw RigError("skinning: output for " + std::to_string(out.size()) + " vertices, the rig has " +
                   std::to_string(rig.vertex_count()));
  std::vector<Mat4> skinning(rig.bindings.size());
  for (std::size_t b = 0; b < rig.bindings.size(); ++b)
    skinning[b] = joint_model[rig.bindings[b].joint] * rig.bindings[b].inverse_bind;
  std::vector<DualQuaternion> dq;
  if (method == SkinningMethod::kDualQuaternion) {
    dq.reserve(skinning.size());
    for (const Mat4& m : skinning) dq.push_back(rigid_dual_quaternion(m));
  }

  const SkinWeights& w = rig.weights;
  for (std::size_t v = 0; v < out.size(); ++v) {
    const std::uint32_t begin = w.offsets[v], end = w.offsets[v + 1];
    const Vec3& x = rig.bind_positions[v];
    if (begin == end) {
      out[v] = x;
      continue;
    }
    if (method == SkinningMethod::kLinearBlend) {
      // Divided by the float weights' sum: identity skinning matrices then give
      // x back to double precision, not to float rounding of the weights.
      Vec3 p = Vec3::Zero();
      double sum = 0.0;
      for (std::uint32_t i = begin; i < end; ++i) {
        const Mat4& m = skinning[w.binding[i]];
        p += static_cast<double>(w.weight[i]) * (m.topLeftCorner<3, 3>() * x + m.topRightCorner<3, 1>());
        sum += static_cast<double>(w.weight[i]);
      }
      out[v] = p / sum;
    } else {
      // Blend in the hemisphere of the first influence (q and −q are one rotation).
      const Eigen::Quaterniond& pivot = dq[w.binding[begin]].r;
      Eigen::Vector4d r = Eigen::Vector4d::Zero(), d = Eigen::Vector4d::Zero();
      for (std::uint32_t i = begin; i < end; ++i) {
        const DualQuaternion& q = dq[w.binding[i]];
        const double s = (q.r.coeffs().dot(pivot.coeffs()) < 0.0 ? -1.0 : 1.0) * static_cast<double>(w.weight[i]);
        r += s * q.r.coeffs();
        d += s * q.d.coeffs();
      }
      const double norm = r.norm();
      if (!(norm > 1e-12)) throw RigError("skinning: vertex " + std::to_string(v) + " has opposite rotations cancelling out");
      const Eigen::Quaterniond qr(r / norm), qd(d / norm);  // coeffs order x y z w
      // Translation = 2 · d · conj(r); rotation = r.
      const Eigen::Quaterniond t = qd * qr.conjugate();
      out[v] = qr * x + 2.0 * Vec3(t.x(), t.y(), t.z());
    }
    if (!out[v].allFinite()) throw RigError("skinning: vertex " + std::to_string(v) + " is not finite");
  }
}

}  // namespace filigree
