#pragma once
// Uniform subdivision (OpenMesh's subdividers) to make million-vertex meshes
// out of real ones for benchmarks.

#include "mesh/tri_mesh.h"

namespace filigree::bench {

// `loop` rounds of Loop subdivision (×4 faces each), then `sqrt3` rounds of
// √3 subdivision (×3 faces each).
TriMesh subdivide(const TriMesh& mesh, int loop, int sqrt3);

}  // namespace filigree::bench
