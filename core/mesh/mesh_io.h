#pragma once
// Reading and writing triangle meshes. Formats are chosen by file extension
// (case-insensitive): read .obj .ply .off .gltf .glb; write .obj .ply .glb.

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/rigged_mesh.h"  // MeshIoError, RiggedMesh
#include "mesh/tri_mesh.h"

namespace filigree {

// Reads a mesh as it is stored: no vertex is welded, no face dropped, polygons
// with more than three corners are fan-triangulated. Indices are NOT checked
// against the vertex count and coordinates are not checked for NaN: that is
// validate_mesh()'s job, so that a bad file gets a precise report. (glTF is
// the exception: primitives are merged, so an index past its own primitive's
// vertices would point into another one and is reported as a MeshIoError.)
// glTF/GLB: every triangle primitive of every mesh instanced by the default
// scene (or scene 0, or every root node if there is no scene) is merged, with
// node transforms applied. Primitives in point or line modes, or without a
// POSITION attribute, are an error.
TriMesh read_mesh(const std::filesystem::path& path);

// Same as read_mesh, from bytes in memory; `format` is an extension such as
// "obj" or ".glb".
TriMesh read_mesh_from_memory(const std::string& bytes, const std::string& format);

// read_mesh / read_mesh_from_memory keeping the skin of a glTF/GLB: every
// skinned primitive's vertices are placed by skinning at the joints' rest
// transforms (what a viewer shows), and the rig says how they move. Other
// formats, and glTF without skins, give no rig. A skin with an invalid joint
// index, weights that do not sum to 1 (within 0.01), joints or inverse bind
// matrices that are missing or not finite is a MeshIoError.
RiggedMesh read_rigged_mesh(const std::filesystem::path& path);
RiggedMesh read_rigged_mesh_from_memory(const std::string& bytes, const std::string& format);

// Writes positions and faces in the given vertex and face order. PLY is binary
// little-endian; GLB stores float32 positions and uint32 indices.
void write_mesh(const TriMesh& mesh, const std::filesystem::path& path);

}  // namespace filigree
