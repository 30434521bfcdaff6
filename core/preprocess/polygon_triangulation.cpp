#include "preprocess/polygon_triangulation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace filigree {
namespace {

using V2 = Eigen::Vector2d;

double cross(const V2& o, const V2& a, const V2& b) { return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x(); }

// Cosine of the smallest angle of triangle abc: the smallest angle is the
// one with the largest cosine (cos falls on [0, π]), so ears compare by it
// without the three atan2 an angle costs.
double min_angle_cosine(const V2& a, const V2& b, const V2& c) {
  const V2 ab = b - a, bc = c - b, ca = a - c;
  const double lab = ab.norm(), lbc = bc.norm(), lca = ca.norm();
  return std::max({-ab.dot(ca) / (lab * lca), -bc.dot(ab) / (lbc * lab), -ca.dot(bc) / (lca * lbc)});
}

bool strictly_inside(const V2& p, const V2& a, const V2& b, const V2& c, double eps) {
  return cross(a, b, p) > eps && cross(b, c, p) > eps && cross(c, a, p) > eps;
}

// In-circle test: is d inside the circumcircle of CCW triangle abc?
bool in_circle(const V2& a, const V2& b, const V2& c, const V2& d) {
  const double ax = a.x() - d.x(), ay = a.y() - d.y();
  const double bx = b.x() - d.x(), by = b.y() - d.y();
  const double cx = c.x() - d.x(), cy = c.y() - d.y();
  const double det = (ax * ax + ay * ay) * (bx * cy - cx * by) - (bx * bx + by * by) * (ax * cy - cx * ay) +
                     (cx * cx + cy * cy) * (ax * by - bx * ay);
  return det > 1e-12 * (ax * ax + ay * ay + bx * bx + by * by + cx * cx + cy * cy);
}

void make_delaunay(std::span<const V2> p, std::vector<std::array<int, 3>>& tris) {
  const std::size_t max_rounds = 4 * tris.size() * tris.size() + 8;
  for (std::size_t round = 0; round < max_rounds; ++round) {
    bool flipped = false;
    for (std::size_t s = 0; s < tris.size() && !flipped; ++s) {
      for (int e = 0; e < 3 && !flipped; ++e) {
        const int a = tris[s][e], b = tris[s][(e + 1) % 3], c = tris[s][(e + 2) % 3];
        for (std::size_t t = s + 1; t < tris.size() && !flipped; ++t) {
          for (int f = 0; f < 3; ++f) {
            if (tris[t][f] != b || tris[t][(f + 1) % 3] != a) continue;
            const int d = tris[t][(f + 2) % 3];
            // Flip ab → cd only when the quad acbd is strictly convex.
            if (in_circle(p[a], p[b], p[c], p[d]) && cross(p[c], p[a], p[d]) > 0 && cross(p[d], p[b], p[c]) > 0) {
              tris[s] = {c, a, d};
              tris[t] = {d, b, c};
              flipped = true;
            }
            break;
          }
        }
      }
    }
    if (!flipped) return;
  }
}

}  // namespace

std::vector<std::array<int, 3>> triangulate_polygon(std::span<const Eigen::Vector2d> polygon) {
  std::vector<std::array<int, 3>> tris;
  triangulate_polygon(polygon, tris);
  return tris;
}

bool triangulate_polygon(std::span<const Eigen::Vector2d> polygon, std::vector<std::array<int, 3>>& tris) {
  tris.clear();
  const int n = static_cast<int>(polygon.size());
  if (n < 3) return false;
  double scale = 0.0;
  for (const V2& q : polygon) scale = std::max(scale, q.cwiseAbs().maxCoeff());
  const double eps = 1e-14 * scale * scale;

  thread_local std::vector<int> live;  // the polygon's corners not yet clipped
  live.resize(n);
  for (int i = 0; i < n; ++i) live[i] = i;
  tris.reserve(n - 2);
  thread_local std::vector<std::uint8_t> convex;  // per live corner
  while (live.size() > 3) {
    const int m = static_cast<int>(live.size());
    convex.resize(m);
    for (int i = 0; i < m; ++i)
      convex[i] = cross(polygon[live[(i + m - 1) % m]], polygon[live[i]], polygon[live[(i + 1) % m]]) > eps;
    int best = -1;
    double best_cosine = 2.0;
    for (int i = 0; i < m; ++i) {
      const int a = live[(i + m - 1) % m], b = live[i], c = live[(i + 1) % m];
      if (!convex[i]) continue;  // reflex or flat corner
      // Only a reflex (or flat) corner can lie in an ear of a simple polygon.
      bool empty = true;
      for (int j = 0; j < m && empty; ++j) {
        const int q = live[j];
        if (!convex[j] && q != a && q != c && strictly_inside(polygon[q], polygon[a], polygon[b], polygon[c], -eps))
          empty = false;
      }
      if (!empty) continue;
      const double cosine = min_angle_cosine(polygon[a], polygon[b], polygon[c]);
      if (cosine < best_cosine) best_cosine = cosine, best = i;
    }
    if (best < 0) {
      tris.clear();
      return false;
    }
    tris.push_back({live[(best + m - 1) % m], live[best], live[(best + 1) % m]});
    live.erase(live.begin() + best);
  }
  if (cross(polygon[live[0]], polygon[live[1]], polygon[live[2]]) <= eps) {
    tris.clear();
    return false;
  }
  tris.push_back({live[0], live[1], live[2]});
  make_delaunay(polygon, tris);
  return true;
}

}  // namespace filigree
