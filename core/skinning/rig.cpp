#include "skinning/rig.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace filigree {
namespace {

// Joint indices reach renderers and clients as 16-bit values (glTF JOINTS_0
// is at most unsigned short), so a rig with more joints cannot be shown.
constexpr std::size_t kMaxJoints = 65535;
constexpr double kUnitTolerance = 1e-3;

// Default stream formatting: 0.7 prints as "0.7", not "0.700000".
template <class... Parts>
std::string cat(const Parts&... parts) {
  std::ostringstream out;
  (out << ... << parts);
  return out.str();
}

[[noreturn]] void fail(const std::string& what) { throw RigError(what); }

template <class Derived>
bool finite(const Eigen::MatrixBase<Derived>& m) {
  return m.allFinite();
}

std::string joint_label(const Rig& rig, std::size_t j) { return cat("joint ", j, " '", rig.joints[j].name, "'"); }

const char* path_name(ClipChannel::Path p) {
  switch (p) {
    case ClipChannel::Path::kTranslation: return "translation";
    case ClipChannel::Path::kRotation: return "rotation";
    case ClipChannel::Path::kScale: return "scale";
  }
  return "unknown path";
}

void validate_transform(const JointTransform& t, const std::string& where) {
  if (!finite(t.translation)) fail(where + ": translation is not finite");
  if (!finite(t.scale)) fail(where + ": scale is not finite");
  if (!finite(t.rotation.coeffs())) fail(where + ": rotation is not finite");
  const double norm = t.rotation.norm();
  if (std::abs(norm - 1.0) > kUnitTolerance) fail(cat(where, ": rotation has norm ", norm, ", not 1"));
}

void validate_joints(const Rig& rig) {
  if (rig.joints.size() > kMaxJoints) fail(cat(rig.joints.size(), " joints, more than the ", kMaxJoints, " a rig may have"));
  for (std::size_t j = 0; j < rig.joints.size(); ++j) {
    const Joint& joint = rig.joints[j];
    if (joint.parent < -1 || (joint.parent >= 0 && static_cast<std::size_t>(joint.parent) >= j))
      fail(cat(joint_label(rig, j), ": parent ", joint.parent, " does not come before it"));
    validate_transform(joint.rest, joint_label(rig, j) + " rest");
    if (!finite(joint.root_parent)) fail(joint_label(rig, j) + ": root parent transform is not finite");
  }
}

void validate_bindings(const Rig& rig) {
  for (std::size_t b = 0; b < rig.bindings.size(); ++b) {
    const Binding& binding = rig.bindings[b];
    if (binding.joint >= rig.joints.size()) fail(cat("binding ", b, ": joint ", binding.joint, " does not exist (", rig.joints.size(), " joints)"));
    if (!finite(binding.inverse_bind)) fail(cat("binding ", b, ": inverse bind matrix is not finite"));
  }
}

void validate_weights(const Rig& rig) {
  const SkinWeights& w = rig.weights;
  if (w.offsets.empty()) fail("weights: no offsets (need vertex count + 1)");
  if (w.offsets.front() != 0) fail(cat("weights: offsets start at ", w.offsets.front(), ", not 0"));
  if (w.binding.size() != w.weight.size())
    fail(cat("weights: ", w.binding.size(), " binding indices but ", w.weight.size(), " weights"));
  for (std::size_t v = 0; v + 1 < w.offsets.size(); ++v)
    if (w.offsets[v + 1] < w.offsets[v]) fail(cat("vertex ", v, ": influence offsets decrease (", w.offsets[v], " then ", w.offsets[v + 1], ")"));
  if (w.offsets.back() != w.binding.size())
    fail(cat("weights: offsets end at ", w.offsets.back(), ", not at the ", w.binding.size(), " influences"));
  if (w.vertex_count() != rig.bind_positions.size())
    fail(cat("weights cover ", w.vertex_count(), " vertices but there are ", rig.bind_positions.size(), " bind positions"));

  for (std::size_t v = 0; v < w.vertex_count(); ++v) {
    if (!finite(rig.bind_positions[v])) fail(cat("vertex ", v, ": bind position is not finite"));
    const std::uint32_t begin = w.offsets[v], end = w.offsets[v + 1];
    if (begin == end) continue;  // not skinned: allowed, it stays at its bind position
    double sum = 0;
    for (std::uint32_t i = begin; i < end; ++i) {
      if (w.binding[i] >= rig.bindings.size())
        fail(cat("vertex ", v, ": influence ", i - begin, " names binding ", w.binding[i], ", but there are ", rig.bindings.size()));
      const float weight = w.weight[i];
      if (!std::isfinite(weight) || weight < 0) fail(cat("vertex ", v, ": weight ", weight, " is negative or not finite"));
      sum += weight;
    }
    if (std::abs(sum - 1.0) > kUnitTolerance) fail(cat("vertex ", v, ": weights sum to ", sum, ", not 1"));
  }
}

void validate_channel(const Rig& rig, const ClipChannel& ch, const std::string& where) {
  if (ch.joint >= rig.joints.size()) fail(cat(where, ": joint ", ch.joint, " does not exist (", rig.joints.size(), " joints)"));
  std::size_t width = 0;
  switch (ch.path) {
    case ClipChannel::Path::kTranslation:
    case ClipChannel::Path::kScale: width = 3; break;
    case ClipChannel::Path::kRotation: width = 4; break;
    default: fail(cat(where, ": unknown path ", static_cast<int>(ch.path)));
  }
  std::size_t per_key = width;
  switch (ch.interpolation) {
    case ClipChannel::Interpolation::kStep:
    case ClipChannel::Interpolation::kLinear: break;
    case ClipChannel::Interpolation::kCubicSpline: per_key *= 3; break;
    default: fail(cat(where, ": unknown interpolation ", static_cast<int>(ch.interpolation)));
  }
  if (ch.times.empty()) fail(where + ": no keys");
  for (std::size_t k = 0; k < ch.times.size(); ++k) {
    if (!std::isfinite(ch.times[k])) fail(cat(where, ": key ", k, " time is not finite"));
    if (k > 0 && !(ch.times[k] > ch.times[k - 1]))
      fail(cat(where, ": key times do not increase at key ", k, " (", ch.times[k], " after ", ch.times[k - 1], ")"));
  }
  if (ch.values.size() != ch.times.size() * per_key)
    fail(cat(where, ": ", ch.values.size(), " values for ", ch.times.size(), " keys, expected ", ch.times.size() * per_key));
  for (std::size_t i = 0; i < ch.values.size(); ++i)
    if (!std::isfinite(ch.values[i])) fail(cat(where, ": value ", i, " (key ", i / per_key, ") is not finite"));
}

void validate_clips(const Rig& rig) {
  for (std::size_t c = 0; c < rig.clips.size(); ++c) {
    const AnimationClip& clip = rig.clips[c];
    for (std::size_t k = 0; k < clip.channels.size(); ++k) {
      const ClipChannel& ch = clip.channels[k];
      validate_channel(rig, ch, cat("clip ", c, " '", clip.name, "' channel ", k, " (", path_name(ch.path), ")"));
    }
  }
}

}  // namespace

Mat4 JointTransform::matrix() const {
  Mat4 m = Mat4::Identity();
  // Normalised: a rotation that passed validation is unit only to 1e-3, and
  // toRotationMatrix() would turn that slack into a scale.
  m.topLeftCorner<3, 3>() = rotation.normalized().toRotationMatrix() * scale.asDiagonal();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

double AnimationClip::duration() const {
  double d = 0;
  for (const ClipChannel& ch : channels)
    if (!ch.times.empty()) d = std::max(d, static_cast<double>(ch.times.back()));
  return d;
}

const AnimationClip* Rig::clip(const std::string& name) const {
  const auto it = std::find_if(clips.begin(), clips.end(), [&](const AnimationClip& c) { return c.name == name; });
  return it == clips.end() ? nullptr : &*it;
}

Rig Rig::restricted_to(const std::vector<Index>& ids) const {
  Rig out;
  out.joints = joints;
  out.bindings = bindings;
  out.clips = clips;
  out.bind_positions.reserve(ids.size());
  out.weights.offsets.reserve(ids.size() + 1);
  // Checked against both arrays so that even an unvalidated rig is never read
  // out of bounds.
  const std::size_t n = std::min(vertex_count(), weights.offsets.empty() ? std::size_t{0} : weights.vertex_count());
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const Index v = ids[i];
    if (v >= n) throw RigError(cat("restricted_to: id ", i, " is vertex ", v, ", but the rig has ", vertex_count(), " vertices"));
    const std::uint32_t begin = weights.offsets[v], end = weights.offsets[v + 1];
    if (begin > end || end > weights.binding.size() || end > weights.weight.size())
      throw RigError(cat("restricted_to: vertex ", v, " has corrupt influence offsets"));
    out.weights.binding.insert(out.weights.binding.end(), weights.binding.begin() + begin, weights.binding.begin() + end);
    out.weights.weight.insert(out.weights.weight.end(), weights.weight.begin() + begin, weights.weight.begin() + end);
    out.weights.offsets.push_back(static_cast<std::uint32_t>(out.weights.binding.size()));
    out.bind_positions.push_back(bind_positions[v]);
  }
  return out;
}

void validate_rig(const Rig& rig) {
  validate_joints(rig);
  validate_bindings(rig);
  validate_weights(rig);
  validate_clips(rig);
}

}  // namespace filigree
