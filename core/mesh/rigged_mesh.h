#pragma once
// What a mesh reader gives (RiggedMesh) and throws (MeshIoError): shared by
// mesh_io (every format) and gltf_io (glTF/GLB), so neither includes the
// other's header.

#include <optional>
#include <stdexcept>

#include "mesh/tri_mesh.h"
#include "skinning/rig.h"

namespace filigree {

// Thrown for unreadable, unsupported or malformed files; what() names the file
// and what is wrong with it.
struct MeshIoError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// A mesh and, for a skinned glTF/GLB, its rig (one entry per mesh vertex).
struct RiggedMesh {
  TriMesh mesh;
  std::optional<Rig> rig;
};

}  // namespace filigree
