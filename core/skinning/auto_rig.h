#pragma once
// A simple automatic rig for meshes that come without one: a chain of joints
// along the mesh's longest axis, weights blending neighbouring bones, and two
// clips. For demos and tests (a real rig comes from the artist's glTF).

#include <cstddef>

#include "mesh/tri_mesh.h"
#include "skinning/rig.h"

namespace filigree {

struct AutoRigOptions {
  std::size_t joints = 4;       // ≥ 2, the chain's length
  double bend_degrees = 60.0;   // total bend of the chain at the clip's extreme
  double clip_seconds = 2.0;    // duration of each clip
};

// A chain along the longest bounding-box axis through the box's centre: joint
// k sits at the start of the k-th of `joints` equal slices. A vertex is
// weighted between the two bones whose slice centres bracket it, with a
// smoothstep blend (weights sum to 1). Clips: "bend" (every joint but the
// root rotates about a perpendicular axis, there and back, LINEAR keys) and
// "twist" (about the chain's axis, CUBICSPLINE keys with zero tangents).
// Throws RigError for fewer than 2 joints or an empty or flat mesh.
Rig auto_rig(const TriMesh& mesh, const AutoRigOptions& options = {});

}  // namespace filigree
