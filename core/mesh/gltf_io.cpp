// glTF 2.0 / GLB through tinygltf (Debian's shared library: no
// TINYGLTF_IMPLEMENTATION here). tinygltf parses the JSON and buffers but does
// not check that accessors stay inside their buffers; every read below is
// bounds-checked so that a corrupt file is an error, not an out-of-bounds read.

#include "mesh/gltf_io.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <new>
#include <string_view>

#include <Eigen/Geometry>
#include <tiny_gltf.h>

#include "mesh/gltf_accessor.h"
#include "mesh/gltf_skin.h"
#include "mesh/json_nesting.h"

namespace filigree {
namespace {

// glTF buffers are little-endian; we copy them with memcpy.
static_assert(std::endian::native == std::endian::little, "glTF reading assumes a little-endian host");

// Geometry only: images are neither decoded nor needed.
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*, int,
                void*) {
  return true;
}

// File-system callbacks for input from memory: nothing outside the bytes given
// may be read.
bool no_file_exists(const std::string&, void*) { return false; }
std::string keep_path(const std::string& path, void*) { return path; }
bool no_read(std::vector<unsigned char>*, std::string* err, const std::string& path, void*) {
  if (err) *err = "external file '" + path + "' not allowed for input from memory";
  return false;
}
bool no_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing is not allowed";
  return false;
}

const char* mode_name(int mode) {
  switch (mode) {
    case TINYGLTF_MODE_POINTS: return "POINTS";
    case TINYGLTF_MODE_LINE: return "LINES";
    case TINYGLTF_MODE_LINE_LOOP: return "LINE_LOOP";
    case TINYGLTF_MODE_LINE_STRIP: return "LINE_STRIP";
    default: return nullptr;
  }
}

class GltfReader {
 public:
  GltfReader(const tinygltf::Model& model, const std::string& name)
      : model_(model), accessors_(model, name) {}

  RiggedMesh read() {
    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      std::size_t scene = 0;
      if (model_.defaultScene >= 0) {
        scene = static_cast<std::size_t>(model_.defaultScene);
        if (scene >= model_.scenes.size()) fail("default scene " + std::to_string(scene) + " does not exist");
      }
      roots = model_.scenes[scene].nodes;
    } else {
      // No scene: every node that is nobody's child is a root.
      std::vector<bool> is_child(model_.nodes.size(), false);
      for (const tinygltf::Node& node : model_.nodes) {
        for (const int child : node.children) {
          if (child >= 0 && static_cast<std::size_t>(child) < is_child.size()) is_child[child] = true;
        }
      }
      for (std::size_t i = 0; i < is_child.size(); ++i) {
        if (!is_child[i]) roots.push_back(static_cast<int>(i));
      }
    }
    add_nodes(roots);
    RiggedMesh result;
    if (!skinned_.empty()) result.rig = read_gltf_rig(model_, accessors_, skinned_, mesh_.positions);
    result.mesh = std::move(mesh_);
    return result;
  }

 private:
  using Elements = GltfAccessors::Elements;

  [[noreturn]] void fail(const std::string& reason) const { accessors_.fail(reason); }

  // Depth-first, parents before children, with an explicit stack so that a deep
  // hierarchy cannot overflow ours. glTF node graphs are trees, so a node seen
  // twice means a cycle or shared node: rejected rather than looping.
  void add_nodes(const std::vector<int>& roots) {
    struct Pending {
      int node;
      Eigen::Affine3d parent;
    };
    std::vector<Pending> stack;
    for (auto it = roots.rbegin(); it != roots.rend(); ++it) stack.push_back({*it, Eigen::Affine3d::Identity()});
    std::vector<bool> visited(model_.nodes.size(), false);
    while (!stack.empty()) {
      const Pending item = stack.back();
      stack.pop_back();
      if (item.node < 0 || static_cast<std::size_t>(item.node) >= model_.nodes.size()) {
        fail("node " + std::to_string(item.node) + " does not exist");
      }
      if (visited[item.node]) fail("node " + std::to_string(item.node) + " occurs twice in the node hierarchy");
      visited[item.node] = true;
      const tinygltf::Node& node = model_.nodes[item.node];
      const Eigen::Affine3d world = item.parent * local_transform(node, item.node);
      // A skinned mesh ignores its node's transform (glTF 2.0 §3.7.3.3): its
      // vertices are read in bind space and posed by the skin afterwards.
      if (node.mesh >= 0) add_mesh(node.mesh, node.skin >= 0 ? Eigen::Affine3d::Identity() : world, item.node, node.skin);
      for (auto it = node.children.rbegin(); it != node.children.rend(); ++it) stack.push_back({*it, world});
    }
  }

  Eigen::Affine3d local_transform(const tinygltf::Node& node, int index) const {
    const std::string what = "node " + std::to_string(index);
    Eigen::Affine3d transform = Eigen::Affine3d::Identity();
    if (!node.matrix.empty()) {
      if (node.matrix.size() != 16) fail(what + ": matrix must have 16 elements");
      transform.matrix() = Eigen::Map<const Eigen::Matrix4d>(node.matrix.data());  // column-major, like glTF
      return transform;
    }
    if (!node.translation.empty()) {
      if (node.translation.size() != 3) fail(what + ": translation must have 3 elements");
      transform.translate(Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]));
    }
    if (!node.rotation.empty()) {
      if (node.rotation.size() != 4) fail(what + ": rotation must have 4 elements");
      // glTF stores x, y, z, w; Eigen's constructor takes w first.
      Eigen::Quaterniond q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
      if (!(q.norm() > 0.0)) fail(what + ": rotation quaternion is zero or not finite");
      transform.rotate(q.normalized());
    }
    if (!node.scale.empty()) {
      if (node.scale.size() != 3) fail(what + ": scale must have 3 elements");
      transform.scale(Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]));
    }
    return transform;
  }

  void add_mesh(int mesh_index, const Eigen::Affine3d& transform, int node, int skin) {
    if (static_cast<std::size_t>(mesh_index) >= model_.meshes.size()) {
      fail("mesh " + std::to_string(mesh_index) + " does not exist");
    }
    const tinygltf::Mesh& mesh = model_.meshes[mesh_index];
    const std::string label = mesh.name.empty() ? "mesh #" + std::to_string(mesh_index) : "mesh '" + mesh.name + "'";
    for (std::size_t p = 0; p < mesh.primitives.size(); ++p) {
      const std::size_t first = mesh_.positions.size();
      const std::string what = "primitive " + std::to_string(p) + " of " + label;
      add_primitive(mesh.primitives[p], what, transform);
      if (skin >= 0) skinned_.push_back({node, skin, first, mesh_.positions.size() - first, &mesh.primitives[p], what});
    }
  }

  void add_primitive(const tinygltf::Primitive& primitive, const std::string& what, const Eigen::Affine3d& transform) {
    const int mode = primitive.mode < 0 ? TINYGLTF_MODE_TRIANGLES : primitive.mode;
    if (const char* name = mode_name(mode)) fail(what + " uses mode " + name + "; only triangle modes are supported");
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
      fail(what + " uses unknown mode " + std::to_string(mode));
    }
    if (primitive.extensions.count("KHR_draco_mesh_compression") != 0) {
      fail(what + " uses KHR_draco_mesh_compression, which is not supported");
    }
    const auto position = primitive.attributes.find("POSITION");
    if (position == primitive.attributes.end()) fail(what + " has no POSITION attribute");

    const tinygltf::Accessor& position_accessor = accessor(position->second, what + " POSITION");
    if (position_accessor.type != TINYGLTF_TYPE_VEC3 ||
        position_accessor.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT) {
      fail(what + ": POSITION must be float VEC3");
    }
    const Elements points = elements(position_accessor, 3 * sizeof(float), what + " POSITION");
    const std::size_t base = mesh_.positions.size();
    if (points.count > static_cast<std::size_t>(std::numeric_limits<Index>::max()) - base) {
      fail("too many vertices for 32-bit indices");
    }
    for (std::size_t i = 0; i < points.count; ++i) {
      float xyz[3];
      std::memcpy(xyz, points.data + i * points.stride, sizeof xyz);
      mesh_.positions.push_back(transform * Eigen::Vector3d(xyz[0], xyz[1], xyz[2]));
    }

    const std::vector<Index> indices = read_indices(primitive, points.count, what);
    // A mirroring transform turns counter-clockwise faces clockwise.
    const bool flip = transform.linear().determinant() < 0.0;
    auto add = [&](Index a, Index b, Index c) {
      const Index offset = static_cast<Index>(base);
      if (flip) std::swap(b, c);
      mesh_.faces.push_back({a + offset, b + offset, c + offset});
    };
    const std::size_t n = indices.size();
    if (mode == TINYGLTF_MODE_TRIANGLES) {
      if (n % 3 != 0) fail(what + ": " + std::to_string(n) + " indices is not a multiple of 3");
      for (std::size_t i = 0; i < n; i += 3) add(indices[i], indices[i + 1], indices[i + 2]);
    } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
      // Odd triangles of a strip are reversed to keep a consistent winding.
      for (std::size_t i = 0; i + 2 < n; ++i) {
        if (i % 2 == 0) add(indices[i], indices[i + 1], indices[i + 2]);
        else add(indices[i], indices[i + 2], indices[i + 1]);
      }
    } else {
      for (std::size_t i = 1; i + 1 < n; ++i) add(indices[0], indices[i], indices[i + 1]);
    }
  }

  // Without an index accessor, vertices are used in order.
  std::vector<Index> read_indices(const tinygltf::Primitive& primitive, std::size_t vertex_count,
                                  const std::string& what) const {
    std::vector<Index> indices;
    if (primitive.indices < 0) {
      indices.resize(vertex_count);
      for (std::size_t i = 0; i < vertex_count; ++i) indices[i] = static_cast<Index>(i);
      return indices;
    }
    // Unsigned byte, short or int scalars, as GltfAccessors::uints reads them.
    const std::vector<std::uint32_t> values = accessors_.uints(primitive.indices, 1, what + " indices");
    indices.assign(values.begin(), values.end());
    for (const Index value : indices) {
      // Primitives are merged with vertex offsets, so an index past this
      // primitive's vertices would silently point into the next one.
      if (value >= vertex_count) {
        fail(what + ": index " + std::to_string(value) + " is out of range (" + std::to_string(vertex_count) +
             " vertices)");
      }
    }
    return indices;
  }

  const tinygltf::Accessor& accessor(int index, const std::string& what) const {
    return accessors_.accessor(index, what);
  }
  Elements elements(const tinygltf::Accessor& a, std::size_t element_size, const std::string& what) const {
    return accessors_.elements(a, element_size, what);
  }

  const tinygltf::Model& model_;
  GltfAccessors accessors_;
  TriMesh mesh_;
  std::vector<SkinnedPrimitive> skinned_;
};

// The JSON a glTF file holds: all of it, or a GLB's first chunk (its length
// at byte 12, its data from byte 20), clipped to the bytes there are. A GLB
// too short for a header has no JSON to scan; tinygltf refuses it.
std::string_view json_text(const std::string& bytes, bool binary) {
  if (!binary) return bytes;
  constexpr std::size_t kHeader = 20;
  if (bytes.size() < kHeader) return {};
  std::uint32_t length = 0;
  std::memcpy(&length, bytes.data() + 12, sizeof length);
  return std::string_view(bytes).substr(kHeader, std::min<std::size_t>(length, bytes.size() - kHeader));
}

}  // namespace

RiggedMesh read_gltf_rigged(const std::string& bytes, bool binary, const std::string& name_for_errors,
                            const std::filesystem::path& base_dir) {
  if (bytes.size() > std::numeric_limits<unsigned int>::max()) {
    throw MeshIoError(name_for_errors + ": file too large for glTF (4 GiB limit)");
  }
  if (json_nesting(json_text(bytes, binary), kMaxJsonNesting) > kMaxJsonNesting)
    throw MeshIoError(name_for_errors + ": invalid " + (binary ? "GLB" : "glTF") + ": its JSON nests deeper than " +
                      std::to_string(kMaxJsonNesting) + " levels");
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&skip_image, nullptr);
  if (base_dir.empty()) loader.SetFsCallbacks({&no_file_exists, &keep_path, &no_read, &no_write, nullptr});
  tinygltf::Model model;
  std::string error, warning;
  bool ok = false;
  try {
    const auto size = static_cast<unsigned int>(bytes.size());
    ok = binary ? loader.LoadBinaryFromMemory(&model, &error, &warning,
                                               reinterpret_cast<const unsigned char*>(bytes.data()), size,
                                               base_dir.string())
                : loader.LoadASCIIFromString(&model, &error, &warning, bytes.data(), size, base_dir.string());
  } catch (const std::bad_alloc&) {
    throw;  // mesh_io reports it as running out of memory, not as a bad file
  } catch (const std::exception& e) {
    // tinygltf's JSON layer may throw on malformed input.
    error = e.what();
  }
  if (!ok) {
    while (!error.empty() && (error.back() == '\n' || error.back() == ' ')) error.pop_back();
    throw MeshIoError(name_for_errors + ": invalid " + (binary ? "GLB" : "glTF") + ": " +
                      (error.empty() ? std::string("unknown error") : error));
  }
  return GltfReader(model, name_for_errors).read();
}

TriMesh read_gltf(const std::string& bytes, bool binary, const std::string& name_for_errors,
                  const std::filesystem::path& base_dir) {
  return read_gltf_rigged(bytes, binary, name_for_errors, base_dir).mesh;
}

void write_glb(const TriMesh& mesh, const std::filesystem::path& path) { write_glb_animation(mesh, {}, 0.0, path); }

void write_glb_animation(const TriMesh& mesh, const std::vector<std::vector<Vec3>>& frames, double fps,
                         const std::filesystem::path& path) {
  const std::string name = path.string();
  // glTF accessors and bufferViews must not be empty.
  if (mesh.positions.empty() || mesh.faces.empty()) throw MeshIoError(name + ": cannot write an empty mesh as GLB");
  if (!frames.empty() && !(fps > 0.0)) throw MeshIoError(name + ": an animation needs a positive frame rate");
  for (const auto& f : frames)
    if (f.size() != mesh.positions.size()) throw MeshIoError(name + ": an animation frame has the wrong vertex count");

  const std::size_t n = mesh.positions.size(), frame_count = frames.size();
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "filigree";
  GlbBuilder glb(model);
  tinygltf::Primitive primitive;
  primitive.attributes["POSITION"] = glb.add_vec3s(mesh.positions, name);
  primitive.indices = glb.add(mesh.faces.data(), mesh.faces.size() * sizeof(Triangle), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                              TINYGLTF_TYPE_SCALAR, mesh.faces.size() * 3, TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);
  primitive.mode = TINYGLTF_MODE_TRIANGLES;
  tinygltf::Mesh gltf_mesh;
  // One morph target per frame (POSITION deltas from the rest mesh), and an
  // animation that shows frame i alone at time i/fps (STEP weights).
  std::vector<Vec3> delta(n);
  for (const auto& frame : frames) {
    for (std::size_t i = 0; i < n; ++i) delta[i] = frame[i] - mesh.positions[i];
    primitive.targets.push_back({{"POSITION", glb.add_vec3s(delta, name)}});
    gltf_mesh.weights.push_back(0.0);
  }
  gltf_mesh.primitives.push_back(primitive);
  model.meshes.push_back(gltf_mesh);
  tinygltf::Node node;
  node.mesh = 0;
  model.nodes.push_back(node);
  if (frame_count > 0) {
    std::vector<float> times(frame_count), weights(frame_count * frame_count, 0.0f);
    for (std::size_t i = 0; i < frame_count; ++i) {
      times[i] = static_cast<float>(static_cast<double>(i) / fps);
      weights[i * frame_count + i] = 1.0f;
    }
    tinygltf::AnimationSampler sampler;
    sampler.input = glb.add(times.data(), times.size() * sizeof(float), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_SCALAR,
                            frame_count, 0, {0.0}, {static_cast<double>(frame_count - 1) / fps});
    sampler.output = glb.add(weights.data(), weights.size() * sizeof(float), TINYGLTF_COMPONENT_TYPE_FLOAT,
                             TINYGLTF_TYPE_SCALAR, weights.size());
    sampler.interpolation = "STEP";
    tinygltf::AnimationChannel channel;
    channel.sampler = 0;
    channel.target_node = 0;
    channel.target_path = "weights";
    tinygltf::Animation animation;
    animation.name = "filigree";
    animation.samplers.push_back(sampler);
    animation.channels.push_back(channel);
    model.animations.push_back(animation);
  }
  tinygltf::Scene scene;
  scene.nodes.push_back(0);
  model.scenes.push_back(scene);
  model.defaultScene = 0;
  save_glb(model, path);
}

}  // namespace filigree
