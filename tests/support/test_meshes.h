#pragma once
// Meshes made in code for tests, and access to the small shipped ones.

#include <string>

#include "mesh/tri_mesh.h"

namespace filigree::test {

// Unit icosphere subdivided `levels` times (12 · 4^levels vertices roughly), closed, genus 0.
TriMesh icosphere(int levels);
// A torus (genus 1) with `rings` × `sides` vertices.
TriMesh torus(int rings, int sides, double major = 1.0, double minor = 0.35);
// An open height field over an (n+1)×(n+1) grid: one boundary loop.
TriMesh wavy_grid(int n);
// Two icospheres side by side: two components.
TriMesh two_spheres(int levels);
// A closed tube along +x from 0 to `length` (a limb), radius `radius`, with
// `rings` × `sides` wall vertices and a centre vertex capping each end.
TriMesh capped_tube(int rings, int sides, double length = 4.0, double radius = 0.5);
// A mesh shipped in tests/data, read with read_mesh.
TriMesh shipped_mesh(const std::string& file_name);
std::string shipped_path(const std::string& file_name);
// A whole file as bytes (e.g. a mesh to upload).
std::string file_bytes(const std::string& path);

}  // namespace filigree::test
