#pragma once
// Distance from points to a triangle surface, for benchmarks that compare a
// coarse surface with a detailed one: a uniform grid over the triangles,
// searched ring by ring around each point until no closer triangle can lie
// farther out.

#include <span>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree::bench {

struct SurfaceDistance {
  double rms = 0.0, max = 0.0;
};

// The distance of every point of `points` to the surface of `triangles`
// (indices into `vertices`): its RMS and max. Preconditions: at least one
// triangle; every index in range.
SurfaceDistance distance_to_surface(std::span<const Vec3> points, std::span<const Vec3> vertices,
                                    std::span<const Triangle> triangles);

}  // namespace filigree::bench
