// glTF 2.0 skins and animations (§3.7.3 skins, §3.11 animations) read into a
// Rig, and a rigged mesh written as GLB (tests and `filigree rig` need files
// with skins; Debian has no public-domain rigged models to ship).

#include "mesh/gltf_skin.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>

#include <tiny_gltf.h>

#include "mesh/gltf_accessor.h"
#include "mesh/gltf_io.h"
#include "skinning/skinning.h"

namespace filigree {
namespace {

constexpr double kWeightSumTolerance = 0.01;  // 8-bit quantised weights sum to 1 within ~4/255

JointTransform node_trs(const tinygltf::Node& node, const GltfAccessors& acc, const std::string& what) {
  JointTransform t;
  if (!node.matrix.empty()) {
    if (node.matrix.size() != 16) acc.fail(what + ": matrix must have 16 elements");
    Eigen::Affine3d m;
    m.matrix() = Eigen::Map<const Eigen::Matrix4d>(node.matrix.data());
    if (!m.matrix().allFinite()) acc.fail(what + ": matrix is not finite");
    Eigen::Matrix3d rotation, scaling;
    m.computeRotationScaling(&rotation, &scaling);
    t.translation = m.translation();
    t.rotation = Eigen::Quaterniond(rotation);
    t.scale = scaling.diagonal();
    return t;
  }
  if (!node.translation.empty()) {
    if (node.translation.size() != 3) acc.fail(what + ": translation must have 3 elements");
    t.translation = Vec3(node.translation[0], node.translation[1], node.translation[2]);
  }
  if (!node.rotation.empty()) {
    if (node.rotation.size() != 4) acc.fail(what + ": rotation must have 4 elements");
    Eigen::Quaterniond q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    if (!(q.norm() > 0.0) || !q.coeffs().allFinite()) acc.fail(what + ": rotation quaternion is zero or not finite");
    t.rotation = q.normalized();
  }
  if (!node.scale.empty()) {
    if (node.scale.size() != 3) acc.fail(what + ": scale must have 3 elements");
    t.scale = Vec3(node.scale[0], node.scale[1], node.scale[2]);
  }
  if (!t.translation.allFinite() || !t.scale.allFinite()) acc.fail(what + ": transform is not finite");
  return t;
}

class RigBuilder {
 public:
  RigBuilder(const tinygltf::Model& model, const GltfAccessors& acc) : model_(model), acc_(acc) {}

  Rig build(const std::vector<SkinnedPrimitive>& skinned, std::vector<Vec3>& positions) {
    link_parents();
    choose_skeleton(skinned);
    add_joints();
    rig_.bind_positions = positions;
    add_weights(skinned, positions.size());
    add_clips();
    try {
      validate_rig(rig_);
      // What a viewer shows at rest: the skin at the nodes' own transforms.
      const std::vector<Mat4> rest = model_transforms(rig_, SkeletonPose::rest(rig_));
      skin(rig_, rest, SkinningMethod::kLinearBlend, positions);
    } catch (const RigError& e) {
      acc_.fail(std::string("skin: ") + e.what());
    }
    return std::move(rig_);
  }

 private:
  std::string node_name(int n) const { return "node " + std::to_string(n); }

  void link_parents() {
    parent_.assign(model_.nodes.size(), -1);
    for (std::size_t n = 0; n < model_.nodes.size(); ++n) {
      for (const int child : model_.nodes[n].children) {
        if (child < 0 || static_cast<std::size_t>(child) >= model_.nodes.size())
          acc_.fail(node_name(static_cast<int>(n)) + ": child " + std::to_string(child) + " does not exist");
        if (parent_[child] != -1) acc_.fail(node_name(child) + " has two parents");
        parent_[child] = static_cast<int>(n);
      }
    }
  }

  // The skins' joints, and every node between two of them (so that a joint
  // below a plain node still follows the joint above it).
  void choose_skeleton(const std::vector<SkinnedPrimitive>& skinned) {
    in_skeleton_.assign(model_.nodes.size(), false);
    for (const SkinnedPrimitive& p : skinned) {
      if (p.skin < 0 || static_cast<std::size_t>(p.skin) >= model_.skins.size())
        acc_.fail(node_name(p.node) + ": skin " + std::to_string(p.skin) + " does not exist");
      if (std::find(skins_.begin(), skins_.end(), p.skin) == skins_.end()) skins_.push_back(p.skin);
    }
    for (const int s : skins_) {
      const tinygltf::Skin& skin = model_.skins[s];
      if (skin.joints.empty()) acc_.fail("skin " + std::to_string(s) + " has no joints");
      for (const int j : skin.joints) {
        if (j < 0 || static_cast<std::size_t>(j) >= model_.nodes.size())
          acc_.fail("skin " + std::to_string(s) + " references node " + std::to_string(j) + ", which does not exist");
        in_skeleton_[j] = true;
      }
    }
    const std::vector<bool> joint = in_skeleton_;
    for (std::size_t n = 0; n < joint.size(); ++n) {
      if (!joint[n]) continue;
      // Walk up to the topmost joint above n; the nodes passed on the way join.
      std::vector<int> path;
      int top = -1;
      std::size_t steps = 0;
      for (int a = parent_[n]; a != -1; a = parent_[a]) {
        if (++steps > model_.nodes.size()) acc_.fail(node_name(static_cast<int>(n)) + ": its ancestors form a cycle");
        path.push_back(a);
        if (joint[a]) top = static_cast<int>(path.size());
      }
      for (int i = 0; i < top; ++i) in_skeleton_[path[i]] = true;
    }
  }

  Mat4 local_matrix(int n) const { return node_trs(model_.nodes[n], acc_, node_name(n)).matrix(); }

  Mat4 world_matrix(int n) const {
    Mat4 m = Mat4::Identity();
    for (; n != -1; n = parent_[n]) m = local_matrix(n) * m;
    return m;
  }

  void add_joints() {
    // Depth-first from the roots so that parents come before children.
    index_of_.assign(model_.nodes.size(), -1);
    std::vector<int> stack;
    for (int n = static_cast<int>(model_.nodes.size()) - 1; n >= 0; --n)
      if (parent_[n] == -1) stack.push_back(n);
    std::size_t visited = 0;
    while (!stack.empty()) {
      const int n = stack.back();
      stack.pop_back();
      if (++visited > model_.nodes.size()) acc_.fail("the node hierarchy has a cycle");
      if (in_skeleton_[n]) {
        const tinygltf::Node& node = model_.nodes[n];
        Joint j;
        j.name = node.name.empty() ? "joint " + std::to_string(rig_.joints.size()) : node.name;
        j.rest = node_trs(node, acc_, node_name(n));
        int a = parent_[n];
        while (a != -1 && !in_skeleton_[a]) a = parent_[a];
        if (a != -1) {
          j.parent = index_of_[a];
        } else if (parent_[n] != -1) {
          j.root_parent = world_matrix(parent_[n]);
        }
        index_of_[n] = static_cast<int>(rig_.joints.size());
        rig_.joints.push_back(std::move(j));
      }
      const auto& children = model_.nodes[n].children;
      for (auto it = children.rbegin(); it != children.rend(); ++it) stack.push_back(*it);
    }
    // Nodes in a cycle are unreachable from any root.
    for (std::size_t n = 0; n < in_skeleton_.size(); ++n)
      if (in_skeleton_[n] && index_of_[n] < 0) acc_.fail(node_name(static_cast<int>(n)) + " is not reachable from a root node");

    for (const int s : skins_) {
      const tinygltf::Skin& skin = model_.skins[s];
      const std::string what = "skin " + std::to_string(s);
      std::vector<float> ibm;
      if (skin.inverseBindMatrices >= 0) {
        ibm = acc_.floats(skin.inverseBindMatrices, 16, what + " inverseBindMatrices");
        if (ibm.size() < 16 * skin.joints.size())
          acc_.fail(what + ": " + std::to_string(ibm.size() / 16) + " inverse bind matrices for " +
                    std::to_string(skin.joints.size()) + " joints");
      }
      std::vector<std::uint32_t>& bindings = bindings_of_[s];
      for (std::size_t k = 0; k < skin.joints.size(); ++k) {
        Binding b;
        b.joint = static_cast<std::uint32_t>(index_of_[skin.joints[k]]);
        if (!ibm.empty()) b.inverse_bind = Eigen::Map<const Eigen::Matrix4f>(ibm.data() + 16 * k).cast<double>();
        bindings.push_back(static_cast<std::uint32_t>(rig_.bindings.size()));
        rig_.bindings.push_back(b);
      }
    }
  }

  void add_weights(const std::vector<SkinnedPrimitive>& skinned, std::size_t vertex_count) {
    // Influences per vertex, then flattened in vertex order.
    std::vector<std::vector<std::pair<std::uint32_t, float>>> influences(vertex_count);
    for (const SkinnedPrimitive& p : skinned) {
      const auto& attributes = p.primitive->attributes;
      const std::vector<std::uint32_t>& bindings = bindings_of_.at(p.skin);
      std::vector<std::vector<std::pair<std::uint32_t, float>>> mine(p.vertex_count);
      for (int set = 0;; ++set) {
        const auto joints = attributes.find("JOINTS_" + std::to_string(set));
        const auto weights = attributes.find("WEIGHTS_" + std::to_string(set));
        if (joints == attributes.end() && weights == attributes.end()) {
          if (set == 0) acc_.fail(p.what + ": its node has a skin but it has no JOINTS_0/WEIGHTS_0");
          break;
        }
        const std::string what = p.what + " JOINTS_" + std::to_string(set) + "/WEIGHTS_" + std::to_string(set);
        if (joints == attributes.end() || weights == attributes.end()) acc_.fail(what + ": one of the pair is missing");
        const std::vector<std::uint32_t> j = acc_.uints(joints->second, 4, what);
        const std::vector<float> w = acc_.floats(weights->second, 4, what);
        if (j.size() != 4 * p.vertex_count || w.size() != 4 * p.vertex_count)
          acc_.fail(what + ": counts differ from the primitive's " + std::to_string(p.vertex_count) + " vertices");
        for (std::size_t v = 0; v < p.vertex_count; ++v) {
          for (int k = 0; k < 4; ++k) {
            const float weight = w[4 * v + k];
            if (weight < 0.0f) acc_.fail(what + ": vertex " + std::to_string(v) + " has a negative weight");
            if (weight == 0.0f) continue;  // unused slot: its joint index may be anything
            const std::uint32_t joint = j[4 * v + k];
            if (joint >= bindings.size())
              acc_.fail(what + ": vertex " + std::to_string(v) + " names joint " + std::to_string(joint) + " of a skin of " +
                        std::to_string(bindings.size()) + " joints");
            mine[v].push_back({bindings[joint], weight});
          }
        }
      }
      for (std::size_t v = 0; v < p.vertex_count; ++v) {
        double sum = 0.0;
        for (const auto& [b, weight] : mine[v]) sum += weight;
        if (std::abs(sum - 1.0) > kWeightSumTolerance)
          acc_.fail(p.what + ": vertex " + std::to_string(v) + " has weights summing to " + std::to_string(sum) +
                    ", not 1 (glTF requires normalised weights)");
        for (auto& [b, weight] : mine[v]) weight = static_cast<float>(weight / sum);
        influences[p.first_vertex + v] = std::move(mine[v]);
      }
    }
    SkinWeights& out = rig_.weights;
    out.offsets.assign(1, 0);
    for (const auto& list : influences) {
      for (const auto& [b, weight] : list) out.binding.push_back(b), out.weight.push_back(weight);
      out.offsets.push_back(static_cast<std::uint32_t>(out.binding.size()));
    }
  }

  void add_clips() {
    for (std::size_t a = 0; a < model_.animations.size(); ++a) {
      const tinygltf::Animation& animation = model_.animations[a];
      const std::string what = "animation " + std::to_string(a);
      AnimationClip clip;
      clip.name = animation.name.empty() ? what : animation.name;
      for (std::size_t c = 0; c < animation.channels.size(); ++c) {
        const tinygltf::AnimationChannel& channel = animation.channels[c];
        const std::string where = what + " channel " + std::to_string(c);
        const int node = channel.target_node;
        if (node < 0 || static_cast<std::size_t>(node) >= model_.nodes.size())
          acc_.fail(where + ": target node " + std::to_string(node) + " does not exist");
        ClipChannel out;
        int components = 3;
        if (channel.target_path == "translation") {
          out.path = ClipChannel::Path::kTranslation;
        } else if (channel.target_path == "rotation") {
          out.path = ClipChannel::Path::kRotation;
          components = 4;
        } else if (channel.target_path == "scale") {
          out.path = ClipChannel::Path::kScale;
        } else {
          continue;  // morph target weights: not a skeleton's motion
        }
        if (!in_skeleton_[node]) continue;  // moves a node the skin does not follow
        out.joint = static_cast<std::uint32_t>(index_of_[node]);
        if (channel.sampler < 0 || static_cast<std::size_t>(channel.sampler) >= animation.samplers.size())
          acc_.fail(where + ": sampler " + std::to_string(channel.sampler) + " does not exist");
        const tinygltf::AnimationSampler& sampler = animation.samplers[channel.sampler];
        if (sampler.interpolation.empty() || sampler.interpolation == "LINEAR") {
          out.interpolation = ClipChannel::Interpolation::kLinear;
        } else if (sampler.interpolation == "STEP") {
          out.interpolation = ClipChannel::Interpolation::kStep;
        } else if (sampler.interpolation == "CUBICSPLINE") {
          out.interpolation = ClipChannel::Interpolation::kCubicSpline;
        } else {
          acc_.fail(where + ": unknown interpolation '" + sampler.interpolation + "'");
        }
        out.times = acc_.floats(sampler.input, 1, where + " input");
        out.values = acc_.floats(sampler.output, components, where + " output");
        clip.channels.push_back(std::move(out));
      }
      if (!clip.channels.empty()) rig_.clips.push_back(std::move(clip));
    }
  }

  const tinygltf::Model& model_;
  const GltfAccessors& acc_;
  std::vector<int> parent_, index_of_, skins_;
  std::vector<bool> in_skeleton_;
  std::map<int, std::vector<std::uint32_t>> bindings_of_;  // skin → binding per skin joint
  Rig rig_;
};

}  // namespace

Rig read_gltf_rig(const tinygltf::Model& model, const GltfAccessors& accessors,
                  const std::vector<SkinnedPrimitive>& skinned, std::vector<Vec3>& positions) {
  return RigBuilder(model, accessors).build(skinned, positions);
}

// ---------------------------------------------------------------- writing

void write_glb_rigged(const TriMesh& bind_mesh, const Rig& rig, const std::filesystem::path& path) {
  const std::string name = path.string();
  if (bind_mesh.positions.empty() || bind_mesh.faces.empty()) throw MeshIoError(name + ": cannot write an empty mesh");
  if (rig.vertex_count() != bind_mesh.vertex_count())
    throw MeshIoError(name + ": the rig has " + std::to_string(rig.vertex_count()) + " vertices, the mesh " +
                      std::to_string(bind_mesh.vertex_count()));
  if (rig.bindings.size() != rig.joints.size())
    throw MeshIoError(name + ": only a rig with one binding per joint (one skin) can be written");
  for (std::size_t j = 0; j < rig.bindings.size(); ++j)
    if (rig.bindings[j].joint != j) throw MeshIoError(name + ": binding j must bind joint j");
  try {
    validate_rig(rig);
  } catch (const RigError& e) {
    throw MeshIoError(name + ": " + e.what());
  }

  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "filigree";
  GlbBuilder glb(model);
  const std::size_t n = bind_mesh.vertex_count();

  tinygltf::Primitive primitive;
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  primitive.attributes["POSITION"] = glb.add_vec3s(bind_mesh.positions, name);
  primitive.indices = glb.add(bind_mesh.faces.data(), bind_mesh.faces.size() * sizeof(Triangle),
                              TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, 3 * bind_mesh.faces.size(),
                              TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);

  // Influences four at a time: JOINTS_0/WEIGHTS_0, JOINTS_1/WEIGHTS_1, …
  std::size_t most = 0;
  for (std::size_t v = 0; v < n; ++v) most = std::max<std::size_t>(most, rig.weights.offsets[v + 1] - rig.weights.offsets[v]);
  for (std::size_t set = 0; set * 4 < std::max<std::size_t>(most, 1); ++set) {
    std::vector<std::uint16_t> joints(4 * n, 0);
    std::vector<float> weights(4 * n, 0.0f);
    for (std::size_t v = 0; v < n; ++v) {
      for (std::size_t k = 0; k < 4; ++k) {
        const std::size_t i = rig.weights.offsets[v] + set * 4 + k;
        if (i >= rig.weights.offsets[v + 1]) break;
        joints[4 * v + k] = static_cast<std::uint16_t>(rig.weights.binding[i]);
        weights[4 * v + k] = rig.weights.weight[i];
      }
    }
    primitive.attributes["JOINTS_" + std::to_string(set)] =
        glb.add(joints.data(), joints.size() * 2, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_VEC4, n,
                TINYGLTF_TARGET_ARRAY_BUFFER);
    primitive.attributes["WEIGHTS_" + std::to_string(set)] =
        glb.add(weights.data(), weights.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC4, n,
                TINYGLTF_TARGET_ARRAY_BUFFER);
  }
  tinygltf::Mesh mesh;
  mesh.primitives.push_back(primitive);
  model.meshes.push_back(mesh);

  // Nodes: joint j is node j; a root with a transform above it gets a parent
  // node holding that transform; the mesh node comes last.
  tinygltf::Scene scene;
  for (const Joint& j : rig.joints) {
    tinygltf::Node node;
    node.name = j.name;
    node.translation = {j.rest.translation.x(), j.rest.translation.y(), j.rest.translation.z()};
    node.rotation = {j.rest.rotation.x(), j.rest.rotation.y(), j.rest.rotation.z(), j.rest.rotation.w()};
    node.scale = {j.rest.scale.x(), j.rest.scale.y(), j.rest.scale.z()};
    model.nodes.push_back(node);
  }
  for (std::size_t j = 0; j < rig.joints.size(); ++j) {
    const Joint& joint = rig.joints[j];
    if (joint.parent >= 0) {
      model.nodes[joint.parent].children.push_back(static_cast<int>(j));
    } else if (joint.root_parent.isIdentity()) {
      scene.nodes.push_back(static_cast<int>(j));
    } else {
      tinygltf::Node above;
      above.matrix.assign(joint.root_parent.data(), joint.root_parent.data() + 16);  // column-major, like glTF
      above.children.push_back(static_cast<int>(j));
      model.nodes.push_back(above);
      scene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));
    }
  }
  std::vector<float> ibm(16 * rig.bindings.size());
  for (std::size_t b = 0; b < rig.bindings.size(); ++b) {
    const Eigen::Matrix4f m = rig.bindings[b].inverse_bind.cast<float>();
    std::copy(m.data(), m.data() + 16, ibm.begin() + static_cast<std::ptrdiff_t>(16 * b));
  }
  tinygltf::Skin skin;
  for (std::size_t j = 0; j < rig.joints.size(); ++j) skin.joints.push_back(static_cast<int>(j));
  skin.inverseBindMatrices =
      glb.add(ibm.data(), ibm.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_MAT4, rig.bindings.size());
  model.skins.push_back(skin);
  tinygltf::Node mesh_node;
  mesh_node.name = "mesh";
  mesh_node.mesh = 0;
  mesh_node.skin = 0;
  model.nodes.push_back(mesh_node);
  scene.nodes.push_back(static_cast<int>(model.nodes.size() - 1));

  for (const AnimationClip& clip : rig.clips) {
    tinygltf::Animation animation;
    animation.name = clip.name;
    for (const ClipChannel& c : clip.channels) {
      const int components = c.path == ClipChannel::Path::kRotation ? 4 : 3;
      tinygltf::AnimationSampler sampler;
      const float first = c.times.front(), last = c.times.back();
      sampler.input = glb.add(c.times.data(), c.times.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR,
                              c.times.size(), 0, {first}, {last});
      sampler.output = glb.add(c.values.data(), c.values.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT,
                               components == 4 ? TINYGLTF_TYPE_VEC4 : TINYGLTF_TYPE_VEC3, c.values.size() / components);
      sampler.interpolation = c.interpolation == ClipChannel::Interpolation::kStep     ? "STEP"
                              : c.interpolation == ClipChannel::Interpolation::kLinear ? "LINEAR"
                                                                                       : "CUBICSPLINE";
      animation.samplers.push_back(sampler);
      tinygltf::AnimationChannel channel;
      channel.sampler = static_cast<int>(animation.samplers.size() - 1);
      channel.target_node = static_cast<int>(c.joint);
      channel.target_path = c.path == ClipChannel::Path::kTranslation ? "translation"
                            : c.path == ClipChannel::Path::kRotation  ? "rotation"
                                                                      : "scale";
      animation.channels.push_back(channel);
    }
    model.animations.push_back(animation);
  }
  model.scenes.push_back(scene);
  model.defaultScene = 0;
  save_glb(model, path);
}

}  // namespace filigree
