#pragma once
// Procedural base-mesh motions for demos, tests and benchmarks.

#include <optional>
#include <string>

#include "mesh/tri_mesh.h"
#include "runtime/pose.h"

namespace filigree {

enum class Motion {
  kBend,   // the half beyond the middle of the longest axis curls by up to 60°
  kTwist,  // twist about the longest axis, ±45° at its ends
  kWave,   // a travelling wave across the longest axis, 3% of the diagonal
  kBump,   // a local bump: vertices near one extreme point pushed out by 5% of the diagonal
};

std::optional<Motion> parse_motion(const std::string& name);  // "bend", "twist", "wave", "bump"
const char* to_string(Motion m);

// The base rest positions moved by `motion` at `phase` in [0, 1] (0 = rest).
Pose procedural_pose(const std::vector<Vec3>& base_rest, Motion motion, double phase);

}  // namespace filigree
