#include "mesh/gltf_accessor.h"

#include <algorithm>
#include <cerrno>
#include <fstream>
#include <limits>
#include <cmath>
#include <cstring>

#include "mesh/rigged_mesh.h"  // MeshIoError

namespace filigree {
namespace {

int component_count(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
  }
}

std::size_t component_size(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    default: return 0;
  }
}

}  // namespace

void GltfAccessors::fail(const std::string& reason) const { throw MeshIoError(name_ + ": " + reason); }

const tinygltf::Accessor& GltfAccessors::accessor(int index, const std::string& what) const {
  if (index < 0 || static_cast<std::size_t>(index) >= model_.accessors.size()) {
    fail(what + ": accessor " + std::to_string(index) + " does not exist");
  }
  const tinygltf::Accessor& result = model_.accessors[index];
  if (result.sparse.isSparse) fail(what + ": sparse accessors are not supported");
  return result;
}

GltfAccessors::Elements GltfAccessors::elements(const tinygltf::Accessor& accessor, std::size_t element_size,
                                                const std::string& what) const {
  if (accessor.bufferView < 0 || static_cast<std::size_t>(accessor.bufferView) >= model_.bufferViews.size()) {
    fail(what + ": accessor has no valid bufferView");
  }
  const tinygltf::BufferView& view = model_.bufferViews[accessor.bufferView];
  if (view.buffer < 0 || static_cast<std::size_t>(view.buffer) >= model_.buffers.size()) {
    fail(what + ": bufferView refers to a missing buffer");
  }
  const std::vector<unsigned char>& buffer = model_.buffers[view.buffer].data;
  if (view.byteOffset > buffer.size() || view.byteLength > buffer.size() - view.byteOffset) {
    fail(what + ": bufferView (offset " + std::to_string(view.byteOffset) + ", length " +
         std::to_string(view.byteLength) + ") exceeds its buffer of " + std::to_string(buffer.size()) + " bytes");
  }
  const std::size_t stride = view.byteStride != 0 ? view.byteStride : element_size;
  if (stride < element_size) {
    fail(what + ": byteStride " + std::to_string(stride) + " is smaller than an element (" +
         std::to_string(element_size) + " bytes)");
  }
  if (accessor.count == 0) return {};
  const std::size_t length = view.byteLength;
  if (accessor.byteOffset > length || element_size > length - accessor.byteOffset ||
      accessor.count - 1 > (length - accessor.byteOffset - element_size) / stride) {
    fail(what + ": accessor (offset " + std::to_string(accessor.byteOffset) + ", " + std::to_string(accessor.count) +
         " elements) reads past the end of its bufferView");
  }
  return {buffer.data() + view.byteOffset + accessor.byteOffset, accessor.count, stride};
}

std::vector<float> GltfAccessors::floats(int index, int components, const std::string& what) const {
  const tinygltf::Accessor& a = accessor(index, what);
  if (component_count(a.type) != components)
    fail(what + ": expected " + std::to_string(components) + " components per element");
  const std::size_t size = component_size(a.componentType);
  const bool is_float = a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT;
  if (size == 0 || a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT || (!is_float && !a.normalized))
    fail(what + ": must be float or normalised (un)signed byte/short");
  const Elements e = elements(a, size * static_cast<std::size_t>(components), what);
  std::vector<float> out(e.count * static_cast<std::size_t>(components));
  for (std::size_t i = 0; i < e.count; ++i) {
    const unsigned char* at = e.data + i * e.stride;
    for (int c = 0; c < components; ++c, at += size) {
      float value = 0.0f;
      switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT: std::memcpy(&value, at, 4); break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: value = static_cast<float>(*at) / 255.0f; break;
        case TINYGLTF_COMPONENT_TYPE_BYTE: {
          std::int8_t v;
          std::memcpy(&v, at, 1);
          value = std::max(static_cast<float>(v) / 127.0f, -1.0f);
          break;
        }
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
          std::uint16_t v;
          std::memcpy(&v, at, 2);
          value = static_cast<float>(v) / 65535.0f;
          break;
        }
        default: {  // SHORT
          std::int16_t v;
          std::memcpy(&v, at, 2);
          value = std::max(static_cast<float>(v) / 32767.0f, -1.0f);
        }
      }
      if (!std::isfinite(value)) fail(what + ": element " + std::to_string(i) + " is not finite");
      out[i * static_cast<std::size_t>(components) + static_cast<std::size_t>(c)] = value;
    }
  }
  return out;
}

std::vector<std::uint32_t> GltfAccessors::uints(int index, int components, const std::string& what) const {
  const tinygltf::Accessor& a = accessor(index, what);
  if (component_count(a.type) != components)
    fail(what + ": expected " + std::to_string(components) + " components per element");
  const std::size_t size = component_size(a.componentType);
  if (a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
      a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
      a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
    fail(what + ": must be unsigned byte, short or int");
  const Elements e = elements(a, size * static_cast<std::size_t>(components), what);
  std::vector<std::uint32_t> out(e.count * static_cast<std::size_t>(components));
  for (std::size_t i = 0; i < e.count; ++i) {
    const unsigned char* at = e.data + i * e.stride;
    for (int c = 0; c < components; ++c, at += size) {
      std::uint32_t value = 0;
      if (size == 1) {
        value = *at;
      } else if (size == 2) {
        std::uint16_t v;
        std::memcpy(&v, at, 2);
        value = v;
      } else {
        std::memcpy(&value, at, 4);
      }
      out[i * static_cast<std::size_t>(components) + static_cast<std::size_t>(c)] = value;
    }
  }
  return out;
}

int GlbBuilder::add(const void* data, std::size_t bytes, int component, int type, std::size_t count, int target,
                    std::vector<double> lo, std::vector<double> hi) {
  std::vector<unsigned char>& buffer = model_.buffers[0].data;
  while (buffer.size() % 4 != 0) buffer.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buffer.size();
  view.byteLength = bytes;
  view.target = target;
  const auto* p = static_cast<const unsigned char*>(data);
  buffer.insert(buffer.end(), p, p + bytes);
  model_.bufferViews.push_back(view);
  tinygltf::Accessor a;
  a.bufferView = static_cast<int>(model_.bufferViews.size() - 1);
  a.componentType = component;
  a.type = type;
  a.count = count;
  a.minValues = std::move(lo);
  a.maxValues = std::move(hi);
  model_.accessors.push_back(a);
  return static_cast<int>(model_.accessors.size() - 1);
}

int GlbBuilder::add_vec3s(std::span<const Vec3> values, const std::string& name) {
  std::vector<float> xyz(3 * values.size());
  std::vector<double> lo(3, std::numeric_limits<double>::infinity()), hi(3, -std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < values.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const float c = static_cast<float>(values[i][k]);
      if (!std::isfinite(c)) throw MeshIoError(name + ": cannot write a non-finite position as GLB");
      lo[k] = std::min(lo[k], double{c});
      hi[k] = std::max(hi[k], double{c});
      xyz[3 * i + k] = c;
    }
  }
  return add(xyz.data(), xyz.size() * sizeof(float), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, values.size(),
             TINYGLTF_TARGET_ARRAY_BUFFER, std::move(lo), std::move(hi));
}

void save_glb(tinygltf::Model& model, const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ofstream file(path, std::ios::binary);
  if (!file) throw MeshIoError(name + ": cannot open for writing: " + std::strerror(errno));
  tinygltf::TinyGLTF writer;
  if (!writer.WriteGltfSceneToStream(&model, file, false, true)) throw MeshIoError(name + ": GLB serialisation failed");
  file.close();
  if (!file) throw MeshIoError(name + ": write failed");
}

}  // namespace filigree
