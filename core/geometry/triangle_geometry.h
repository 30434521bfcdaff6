#pragma once
// Per-triangle measures shared by preprocessing and runtime.

#include "mesh/tri_mesh.h"

namespace filigree {

// Cross product (b − a) × (c − a): twice the area, along the normal.
Vec3 triangle_area_vector(const Vec3& a, const Vec3& b, const Vec3& c);

double triangle_area(const Vec3& a, const Vec3& b, const Vec3& c);

// Shape quality in [0, 1]: 4√3·area / Σ edge², 1 for equilateral, 0 for degenerate.
double triangle_quality(const Vec3& a, const Vec3& b, const Vec3& c);

// Cotangent of the angle at `apex` in triangle (apex, b, c). The sine is floored
// at 1e-12 of the edge-length product, so degenerate triangles give a large but
// finite value instead of Inf/NaN.
double cotangent_at(const Vec3& apex, const Vec3& b, const Vec3& c);

// Angle at `apex` in radians, in [0, π].
double angle_at(const Vec3& apex, const Vec3& b, const Vec3& c);

}  // namespace filigree
