#pragma once
// Triangulation of the small planar polygon left by a vertex removal.

#include <array>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace filigree {

// Triangulates a simple counter-clockwise polygon (no repeated vertices) into
// n − 2 counter-clockwise triangles of polygon indices, using only polygon
// vertices. Ears are clipped best-first (largest smallest angle), then
// diagonals are flipped until the triangulation is Delaunay inside the polygon,
// which gives the well-shaped triangles vertex removal needs.
// Returns an empty vector if the polygon is not simple or is degenerate.
std::vector<std::array<int, 3>> triangulate_polygon(std::span<const Eigen::Vector2d> polygon);
// The same into `tris` (reusing its storage); false, and `tris` empty, when
// the polygon is not simple or is degenerate.
bool triangulate_polygon(std::span<const Eigen::Vector2d> polygon, std::vector<std::array<int, 3>>& tris);

}  // namespace filigree
