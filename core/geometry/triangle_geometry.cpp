#include "geometry/triangle_geometry.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

namespace filigree {

Vec3 triangle_area_vector(const Vec3& a, const Vec3& b, const Vec3& c) { return (b - a).cross(c - a); }

double triangle_area(const Vec3& a, const Vec3& b, const Vec3& c) { return 0.5 * triangle_area_vector(a, b, c).norm(); }

double triangle_quality(const Vec3& a, const Vec3& b, const Vec3& c) {
  const double sum_sq = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  if (!(sum_sq > 0.0)) return 0.0;
  return 4.0 * std::sqrt(3.0) * triangle_area(a, b, c) / sum_sq;
}

double cotangent_at(const Vec3& apex, const Vec3& b, const Vec3& c) {
  const Vec3 u = b - apex, v = c - apex;
  const double len = u.norm() * v.norm();
  const double sine = std::max(u.cross(v).norm(), 1e-12 * len);
  if (!(sine > 0.0)) return 0.0;  // a zero-length edge: no angle to speak of
  return u.dot(v) / sine;
}

double angle_at(const Vec3& apex, const Vec3& b, const Vec3& c) {
  const Vec3 u = b - apex, v = c - apex;
  return std::atan2(u.cross(v).norm(), u.dot(v));
}

}  // namespace filigree
