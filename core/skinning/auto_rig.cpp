#include "skinning/auto_rig.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace filigree {
namespace {

// Keys of a there-and-back rotation about `axis` by up to `angle` radians.
ClipChannel swing(std::uint32_t joint, const Vec3& axis, double angle, double seconds, bool cubic) {
  constexpr int kKeys = 9;
  ClipChannel c;
  c.joint = joint;
  c.path = ClipChannel::Path::kRotation;
  c.interpolation = cubic ? ClipChannel::Interpolation::kCubicSpline : ClipChannel::Interpolation::kLinear;
  for (int k = 0; k < kKeys; ++k) {
    const double t = seconds * k / (kKeys - 1);
    const Eigen::Quaterniond q(Eigen::AngleAxisd(angle * std::sin(2.0 * M_PI * k / (kKeys - 1)), axis));
    c.times.push_back(static_cast<float>(t));
    if (cubic) c.values.insert(c.values.end(), {0.0f, 0.0f, 0.0f, 0.0f});  // in-tangent
    c.values.insert(c.values.end(), {static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()),
                                     static_cast<float>(q.w())});
    if (cubic) c.values.insert(c.values.end(), {0.0f, 0.0f, 0.0f, 0.0f});  // out-tangent
  }
  return c;
}

}  // namespace

Rig auto_rig(const TriMesh& mesh, const AutoRigOptions& o) {
  if (o.joints < 2) throw RigError("auto rig: a chain needs at least 2 joints");
  if (mesh.positions.empty()) throw RigError("auto rig: the mesh is empty");
  Vec3 lo = mesh.positions.front(), hi = lo;
  for (const Vec3& p : mesh.positions) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  int axis = 0;
  (hi - lo).maxCoeff(&axis);
  const double length = (hi - lo)[axis];
  if (!(length > 0.0) || !std::isfinite(length)) throw RigError("auto rig: the mesh is flat or not finite");
  const Vec3 along = Vec3::Unit(axis), across = Vec3::Unit((axis + 1) % 3);
  const double slice = length / static_cast<double>(o.joints);
  Vec3 start = 0.5 * (lo + hi);
  start[axis] = lo[axis];

  Rig rig;
  for (std::size_t k = 0; k < o.joints; ++k) {
    Joint j;
    j.name = "bone" + std::to_string(k);
    j.parent = static_cast<std::int32_t>(k) - 1;
    j.rest.translation = k == 0 ? start : Vec3(slice * along);
    rig.joints.push_back(j);
    Binding b;
    b.joint = static_cast<std::uint32_t>(k);
    b.inverse_bind = Mat4::Identity();
    b.inverse_bind.topRightCorner<3, 1>() = -(start + static_cast<double>(k) * slice * along);
    rig.bindings.push_back(b);
  }
  rig.bind_positions = mesh.positions;
  SkinWeights& w = rig.weights;
  for (const Vec3& p : mesh.positions) {
    // u = k at the centre of slice k; blend bones k and k + 1 in between.
    const double u = std::clamp((p[axis] - lo[axis]) / slice - 0.5, 0.0, static_cast<double>(o.joints - 1));
    const std::size_t k = std::min(static_cast<std::size_t>(u), o.joints - 2);
    const double f = u - static_cast<double>(k), s = f * f * (3.0 - 2.0 * f);
    if (s < 1.0) w.binding.push_back(static_cast<std::uint32_t>(k)), w.weight.push_back(static_cast<float>(1.0 - s));
    if (s > 0.0) w.binding.push_back(static_cast<std::uint32_t>(k + 1)), w.weight.push_back(static_cast<float>(s));
    w.offsets.push_back(static_cast<std::uint32_t>(w.binding.size()));
  }

  const double per_joint = o.bend_degrees * M_PI / 180.0 / static_cast<double>(o.joints - 1);
  AnimationClip bend{"bend", {}}, twist{"twist", {}};
  for (std::size_t k = 1; k < o.joints; ++k) {
    bend.channels.push_back(swing(static_cast<std::uint32_t>(k), across, per_joint, o.clip_seconds, false));
    twist.channels.push_back(swing(static_cast<std::uint32_t>(k), along, per_joint, o.clip_seconds, true));
  }
  rig.clips = {bend, twist};
  validate_rig(rig);
  return rig;
}

}  // namespace filigree
