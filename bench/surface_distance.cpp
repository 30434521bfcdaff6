#include "bench/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace filigree::bench {
namespace {

// The closest point of triangle abc to p (Ericson, Real-Time Collision
// Detection, §5.1.5).
Vec3 closest_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

}  // namespace

SurfaceDistance distance_to_surface(std::span<const Vec3> points, std::span<const Vec3> vertices,
                                    std::span<const Triangle> triangles) {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const Vec3& v : vertices) lo = lo.cwiseMin(v), hi = hi.cwiseMax(v);
  for (const Vec3& p : points) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  // About two triangles a cell.
  const Vec3 size = (hi - lo).cwiseMax(1e-12);
  const double cell = std::cbrt(size.prod() / std::max<double>(1.0, static_cast<double>(triangles.size()) / 2.0));
  const Eigen::Vector3i dims = ((size / cell).array().floor().cast<int>() + 1).matrix();
  const auto cell_of = [&](const Vec3& p) {
    return ((p - lo) / cell).array().floor().cast<int>().max(0).min(dims.array() - 1).matrix().eval();
  };
  const auto index = [&](int x, int y, int z) { return (static_cast<std::size_t>(z) * dims.y() + y) * dims.x() + x; };
  std::vector<std::vector<std::uint32_t>> cells(static_cast<std::size_t>(dims.prod()));
  for (std::uint32_t t = 0; t < triangles.size(); ++t) {
    const Vec3 &a = vertices[triangles[t][0]], &b = vertices[triangles[t][1]], &c = vertices[triangles[t][2]];
    const Eigen::Vector3i from = cell_of(a.cwiseMin(b).cwiseMin(c)), to = cell_of(a.cwiseMax(b).cwiseMax(c));
    for (int z = from.z(); z <= to.z(); ++z)
      for (int y = from.y(); y <= to.y(); ++y)
        for (int x = from.x(); x <= to.x(); ++x) cells[index(x, y, z)].push_back(t);
  }
  SurfaceDistance out;
  double sum = 0.0;
  for (const Vec3& p : points) {
    const Eigen::Vector3i home = cell_of(p);
    double best = std::numeric_limits<double>::infinity();
    // Ring r holds the cells at Chebyshev distance r; a triangle first seen
    // in ring r + 1 or later is farther than r cells away.
    for (int r = 0; r <= dims.maxCoeff(); ++r) {
      for (int z = home.z() - r; z <= home.z() + r; ++z)
        for (int y = home.y() - r; y <= home.y() + r; ++y)
          for (int x = home.x() - r; x <= home.x() + r; ++x) {
            if (std::max({std::abs(x - home.x()), std::abs(y - home.y()), std::abs(z - home.z())}) != r) continue;
            if (x < 0 || y < 0 || z < 0 || x >= dims.x() || y >= dims.y() || z >= dims.z()) continue;
            for (std::uint32_t t : cells[index(x, y, z)]) {
              const Triangle& f = triangles[t];
              best = std::min(best, (p - closest_on_triangle(p, vertices[f[0]], vertices[f[1]], vertices[f[2]])).squaredNorm());
            }
          }
      if (best <= std::pow(r * cell, 2)) break;
    }
    const double d = std::sqrt(best);
    sum += d * d;
    out.max = std::max(out.max, d);
  }
  out.rms = points.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(points.size()));
  return out;
}

}  // namespace filigree::bench
