#pragma once
// Pose files: the project's documented pose format.
//
// A pose gives one position per base vertex, in base order (the order of
// `filigree export-base` and of Hierarchy::base_vertices). Two forms are read:
//
//  * `.pose` — raw binary, no header: for base vertex 0, 1, …, m−1 the three
//    coordinates x, y, z as IEEE-754 float32, little-endian. The file is exactly
//    12·m bytes. Example (Python): numpy.asarray(p, '<f4').tofile("a.pose").
//  * a mesh file (.obj .ply .off .gltf .glb, see mesh_io.h) of the posed base
//    mesh, e.g. the output of `filigree export-base` moved in a modelling tool:
//    only its vertex positions are used, in file order; its faces are ignored.
//
// Only `.pose` is written.

#include <cstddef>
#include <filesystem>

#include "runtime/pose.h"

namespace filigree {

// Reads a pose for a base mesh of `base_vertex_count` vertices. Throws PoseError
// naming the file if it cannot be read, has an unsupported extension, has the
// wrong size or vertex count, or holds a NaN/Inf coordinate (validate_pose).
Pose read_pose(const std::filesystem::path& path, std::size_t base_vertex_count);

// Writes `pose` as a `.pose` file (coordinates rounded to float32). Throws
// PoseError if the extension is not .pose, a coordinate is not finite or does
// not fit in a float32, or the file cannot be written.
void write_pose(const Pose& pose, const std::filesystem::path& path);

}  // namespace filigree
