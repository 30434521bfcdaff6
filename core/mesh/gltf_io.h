#pragma once
// glTF 2.0 / GLB support behind mesh_io.h, and animated GLB output.

#include <filesystem>
#include <string>
#include <vector>

#include "mesh/rigged_mesh.h"
#include "mesh/tri_mesh.h"

namespace filigree {

// Parses a .gltf (JSON, `binary` false) or .glb document held in `bytes` as
// described for read_mesh(). External buffer files are looked up relative to
// `base_dir`; with an empty base_dir (input from memory) every external file
// reference is refused, so a document cannot make us read arbitrary files.
// Throws MeshIoError whose message starts with `name_for_errors`.
TriMesh read_gltf(const std::string& bytes, bool binary, const std::string& name_for_errors,
                  const std::filesystem::path& base_dir = {});
// The same, with the rig of skinned primitives (see read_rigged_mesh()).
RiggedMesh read_gltf_rigged(const std::string& bytes, bool binary, const std::string& name_for_errors,
                            const std::filesystem::path& base_dir = {});

// Writes one mesh / primitive / node / scene with float32 positions and uint32
// indices in a single binary buffer. Throws MeshIoError on failure.
void write_glb(const TriMesh& mesh, const std::filesystem::path& path);

// The same with an animation: one morph target per frame (POSITION deltas
// from `mesh`), played by an animation channel that shows frame i alone at
// time i / fps. Every frame must have one position per vertex.
void write_glb_animation(const TriMesh& mesh, const std::vector<std::vector<Vec3>>& frames, double fps,
                         const std::filesystem::path& path);

// Writes a skinned mesh: `bind_mesh` holds the bind positions (rig.bind_positions
// must equal them), one skin binding every joint (rig.bindings[j].joint == j),
// joints as nodes with their rest TRS, weights as JOINTS_n/WEIGHTS_n (4 per
// set), and the rig's clips as animations. Throws MeshIoError on failure.
void write_glb_rigged(const TriMesh& bind_mesh, const Rig& rig, const std::filesystem::path& path);

}  // namespace filigree
