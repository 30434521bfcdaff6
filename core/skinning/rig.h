#pragma once
// A rig: the skeleton of a skinned mesh, each vertex's joint weights, and the
// animation clips that came with it (glTF 2.0 skins and animations, issue 13).
//
// Conventions (glTF's): a joint's local transform is translation · rotation ·
// scale relative to its parent; a joint's *model* transform is the product of
// the locals from its root down, times the fixed transform above the root
// (Joint::root_parent, the non-joint nodes above it at rest). A vertex skins as
//   x' = Σ_i w_i · M_{j_i} · B_{b_i} · x_bind
// with M the model transform of the binding's joint and B its inverse bind
// matrix (linear blend skinning; dual quaternions blend the same M·B).

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "mesh/tri_mesh.h"

namespace filigree {

using Mat4 = Eigen::Matrix4d;

// A local transform, translation · rotation · scale (glTF node TRS).
struct JointTransform {
  Vec3 translation = Vec3::Zero();
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Vec3 scale = Vec3::Ones();

  Mat4 matrix() const;
};

struct Joint {
  std::string name;
  std::int32_t parent = -1;  // a joint before this one, or -1 for a root
  JointTransform rest;       // the local transform at rest (the file's node TRS)
  // Roots only: the model transform of the nodes above this joint (identity
  // when it is a scene root).
  Mat4 root_parent = Mat4::Identity();
};

// A joint and the inverse bind matrix one glTF skin gives it. Several skins
// may bind the same joint differently, hence bindings, not joints, in weights.
struct Binding {
  std::uint32_t joint = 0;
  Mat4 inverse_bind = Mat4::Identity();
};

// One animated property of one joint (glTF animation channel + sampler).
struct ClipChannel {
  enum class Path : std::uint8_t { kTranslation, kRotation, kScale };
  enum class Interpolation : std::uint8_t { kStep, kLinear, kCubicSpline };
  std::uint32_t joint = 0;
  Path path = Path::kTranslation;
  Interpolation interpolation = Interpolation::kLinear;
  std::vector<float> times;  // seconds, strictly increasing, ≥ 1 key
  // Per key: 3 (translation, scale) or 4 (rotation, x y z w) floats; cubic
  // splines store in-tangent, value, out-tangent per key (3× as many).
  std::vector<float> values;
};

struct AnimationClip {
  std::string name;
  std::vector<ClipChannel> channels;
  double duration() const;  // the last key time over all channels (0 if none)
};

// Influences of vertex v: [offsets[v], offsets[v+1]) in `binding` and
// `weight`; weights of a vertex sum to 1. A vertex without influences is not
// skinned: it stays at its bind position.
struct SkinWeights {
  std::vector<std::uint32_t> offsets{0};  // vertex_count + 1
  std::vector<std::uint32_t> binding;
  std::vector<float> weight;

  std::size_t vertex_count() const { return offsets.size() - 1; }
};

struct Rig {
  std::vector<Joint> joints;  // parents before children
  std::vector<Binding> bindings;
  SkinWeights weights;               // per vertex of the mesh the rig belongs to
  std::vector<Vec3> bind_positions;  // per vertex: the position the weights apply to
  std::vector<AnimationClip> clips;

  std::size_t vertex_count() const { return bind_positions.size(); }
  // The clip called `name`, or null.
  const AnimationClip* clip(const std::string& name) const;
  // The same rig for the vertices `ids` (vertex i of the result is vertex
  // ids[i] of this one): the base mesh's rig from the detailed mesh's.
  Rig restricted_to(const std::vector<Index>& ids) const;
};

// A rig that cannot be used; what() says what is wrong.
struct RigError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

// Throws RigError unless: parents come before children, bindings name
// existing joints, every matrix and transform is finite with a unit-norm
// rotation, each vertex's weights are ≥ 0, name existing bindings and sum to
// 1 within 1e-3, bind positions are finite and one per weighted vertex, and
// clip channels name existing joints with increasing finite times and the
// right number of finite values.
void validate_rig(const Rig& rig);

}  // namespace filigree
