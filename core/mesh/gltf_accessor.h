#pragma once
// Bounds-checked reading of glTF accessors (internal to core/mesh: includes
// tinygltf). tinygltf parses buffers but does not check that accessors stay
// inside them; everything read through here is checked, so a corrupt file is
// a MeshIoError, never an out-of-bounds read.

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include <tiny_gltf.h>

#include "mesh/tri_mesh.h"

namespace filigree {

class GltfAccessors {
 public:
  // Errors are reported as MeshIoError("<name>: <what>: …").
  GltfAccessors(const tinygltf::Model& model, const std::string& name) : model_(model), name_(name) {}

  struct Elements {
    const unsigned char* data = nullptr;
    std::size_t count = 0;
    std::size_t stride = 0;
  };

  [[noreturn]] void fail(const std::string& reason) const;

  // Accessor `index`; sparse accessors are refused.
  const tinygltf::Accessor& accessor(int index, const std::string& what) const;
  // The accessor's elements, each `element_size` bytes, all inside its
  // bufferView and the bufferView inside its buffer.
  Elements elements(const tinygltf::Accessor& accessor, std::size_t element_size, const std::string& what) const;

  // Accessor `index` as floats, `components` per element (its type must have
  // that many): float, or normalised (un)signed byte/short as glTF defines
  // them (e.g. max(c / 127, −1) for signed bytes). Every value finite.
  std::vector<float> floats(int index, int components, const std::string& what) const;
  // Accessor `index` as unsigned integers, `components` per element:
  // unsigned byte, short or int.
  std::vector<std::uint32_t> uints(int index, int components, const std::string& what) const;

 private:
  const tinygltf::Model& model_;
  const std::string& name_;
};

// Builds a GLB's single buffer: each add() appends data (4-byte aligned) as
// one bufferView and one accessor, and returns the accessor's index.
class GlbBuilder {
 public:
  explicit GlbBuilder(tinygltf::Model& model) : model_(model) { model_.buffers.resize(1); }
  int add(const void* data, std::size_t bytes, int component, int type, std::size_t count, int target = 0,
          std::vector<double> lo = {}, std::vector<double> hi = {});
  // Float32 VEC3s with their min/max (glTF requires them for POSITION, and
  // JSON cannot hold NaN/Inf): throws MeshIoError("<name>: …") for a
  // value that is not finite as a float.
  int add_vec3s(std::span<const Vec3> values, const std::string& name);

 private:
  tinygltf::Model& model_;
};

// Writes `model` as a GLB file; throws MeshIoError if the file cannot be
// created or written (tinygltf's own file writer ignores stream errors).
void save_glb(tinygltf::Model& model, const std::filesystem::path& path);

}  // namespace filigree
