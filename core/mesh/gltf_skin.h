#pragma once
// glTF skins and animations → Rig (internal to core/mesh: gltf_io.cpp reads
// the geometry, this the skin of what it read).

#include <cstddef>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"
#include "skinning/rig.h"

namespace tinygltf {
class Model;
struct Primitive;
}  // namespace tinygltf

namespace filigree {

class GltfAccessors;

// A primitive of a skinned node, read into vertices [first_vertex,
// first_vertex + vertex_count) of the mesh in bind space.
struct SkinnedPrimitive {
  int node = -1, skin = -1;
  std::size_t first_vertex = 0, vertex_count = 0;
  const tinygltf::Primitive* primitive = nullptr;
  std::string what;  // for messages: "primitive 0 of mesh 'body'"
};

// The rig of `positions` (every vertex of the merged mesh): the skeleton is
// every skin's joints plus the nodes between them, parents first; weights
// come from each skinned primitive's JOINTS_n/WEIGHTS_n; vertices of
// unskinned primitives get none. Moves the skinned vertices of `positions`
// to their rest pose (skinned at the nodes' own transforms). Clips: the
// file's animations, keeping the channels that move skeleton nodes.
// Throws MeshIoError naming the file and what is wrong.
Rig read_gltf_rig(const tinygltf::Model& model, const GltfAccessors& accessors,
                  const std::vector<SkinnedPrimitive>& skinned, std::vector<Vec3>& positions);

}  // namespace filigree
