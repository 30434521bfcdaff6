// The geometric building blocks of vertex removal and direct recovery.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <map>
#include <numbers>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "geometry/cotangent_laplacian.h"
#include "geometry/ring_frame.h"
#include "geometry/ring_weights.h"
#include "geometry/triangle_geometry.h"
#include "preprocess/conformal_ring_map.h"
#include "preprocess/polygon_triangulation.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

double signed_area(const Vec2& a, const Vec2& b, const Vec2& c) {
  return 0.5 * ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x());
}

double polygon_area(const std::vector<Vec2>& p) {
  double a = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) a += signed_area(Vec2::Zero(), p[i], p[(i + 1) % p.size()]);
  return a;
}

void expect_valid_triangulation(const std::vector<Vec2>& polygon) {
  const auto tris = triangulate_polygon(polygon);
  ASSERT_EQ(tris.size(), polygon.size() - 2);
  double area = 0.0;
  for (const auto& t : tris) {
    const double a = signed_area(polygon[t[0]], polygon[t[1]], polygon[t[2]]);
    EXPECT_GT(a, 0.0) << "triangle is not counter-clockwise";
    area += a;
  }
  // Positive triangles covering exactly the polygon's area: no overlap, no gap.
  EXPECT_NEAR(area, polygon_area(polygon), 1e-12);
}

TEST(PolygonTriangulation, ConvexAndStarShapedPolygons) {
  std::vector<Vec2> hexagon;
  for (int i = 0; i < 6; ++i) hexagon.emplace_back(std::cos(i * std::numbers::pi / 3), std::sin(i * std::numbers::pi / 3));
  expect_valid_triangulation(hexagon);

  std::vector<Vec2> star;  // 5-pointed star: five reflex corners
  for (int i = 0; i < 10; ++i) {
    const double r = i % 2 ? 0.4 : 1.0, a = i * std::numbers::pi / 5;
    star.emplace_back(r * std::cos(a), r * std::sin(a));
  }
  expect_valid_triangulation(star);
}

TEST(PolygonTriangulation, DelaunayFlipsAvoidSlivers) {
  // A long thin quad: 0-2 is the short, well-shaped diagonal.
  const std::vector<Vec2> quad = {{0, 0}, {1, -0.1}, {2, 0}, {1, 0.1}};
  const auto tris = triangulate_polygon(quad);
  ASSERT_EQ(tris.size(), 2u);
  for (const auto& t : tris) {
    const bool has0 = std::find(t.begin(), t.end(), 0) != t.end(), has2 = std::find(t.begin(), t.end(), 2) != t.end();
    EXPECT_FALSE(has0 && has2) << "kept the long diagonal";
  }
}

TEST(PolygonTriangulation, RejectsClockwiseAndDegenerateInput) {
  EXPECT_TRUE(triangulate_polygon(std::vector<Vec2>{{0, 0}, {0, 1}, {1, 1}, {1, 0}}).empty());
  EXPECT_TRUE(triangulate_polygon(std::vector<Vec2>{{0, 0}, {1, 0}, {2, 0}}).empty());
  EXPECT_TRUE(triangulate_polygon(std::vector<Vec2>{{0, 0}, {1, 0}}).empty());
}

TEST(ConformalRingMap, PlanarFanKeepsItsAnglesAndIsCounterClockwise) {
  std::vector<Vec3> x = {Vec3::Zero()};
  std::vector<Index> ring;
  for (int i = 0; i < 6; ++i) {
    x.emplace_back(std::cos(i * std::numbers::pi / 3), std::sin(i * std::numbers::pi / 3), 0.0);
    ring.push_back(static_cast<Index>(i + 1));
  }
  const auto uv = conformal_ring_map(x[0], ring, x, true);
  ASSERT_EQ(uv.size(), 6u);
  for (int i = 0; i < 6; ++i) {
    EXPECT_NEAR(uv[i].norm(), 1.0, 1e-12);
    EXPECT_NEAR(std::atan2(uv[i].y(), uv[i].x()), std::remainder(i * std::numbers::pi / 3, 2 * std::numbers::pi), 1e-12);
  }
}

TEST(ConformalRingMap, ConeOpensToAFullTurnAndBoundaryToAHalfTurn) {
  // A cone: the ring is lifted, so the 3D angles sum to less than 2π.
  std::vector<Vec3> x = {Vec3(0, 0, 1)};
  std::vector<Index> ring;
  for (int i = 0; i < 5; ++i) {
    x.emplace_back(std::cos(i * 2 * std::numbers::pi / 5), std::sin(i * 2 * std::numbers::pi / 5), 0.0);
    ring.push_back(static_cast<Index>(i + 1));
  }
  const auto uv = conformal_ring_map(x[0], ring, x, true);
  ASSERT_EQ(uv.size(), 5u);
  EXPECT_NEAR(std::atan2(uv[1].y(), uv[1].x()), 2 * std::numbers::pi / 5, 1e-12);
  EXPECT_FALSE(triangulate_polygon(uv).empty());

  const std::vector<Index> open = {1, 2, 3};
  const auto half = conformal_ring_map(x[0], open, x, false);
  ASSERT_EQ(half.size(), 3u);
  EXPECT_NEAR(half[0].y(), 0.0, 1e-12);
  EXPECT_GT(half[0].x(), 0.0);
  EXPECT_EQ(half[2].y(), 0.0);
  EXPECT_LT(half[2].x(), 0.0);
  EXPECT_GT(half[1].y(), 0.0);
}

TEST(RingWeights, RegularFanIsUniformAndDegenerateFansStayPositive) {
  std::vector<Vec3> x = {Vec3::Zero()};
  std::vector<Index> ring;
  for (int i = 0; i < 6; ++i) {
    x.emplace_back(std::cos(i * std::numbers::pi / 3), std::sin(i * std::numbers::pi / 3), 0.0);
    ring.push_back(static_cast<Index>(i + 1));
  }
  for (double w : ring_weights(x[0], ring, x, true)) EXPECT_NEAR(w, 1.0 / 6.0, 1e-12);

  // Very obtuse fan: the centre almost on a ring edge makes cotangents negative.
  std::vector<Vec3> y = {Vec3(0, -0.999, 0), Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0)};
  const std::vector<Index> square = {1, 2, 3, 4};
  double sum = 0.0;
  for (double w : ring_weights(y[0], square, y, true)) {
    EXPECT_TRUE(std::isfinite(w));
    EXPECT_GT(w, 0.0);
    sum += w;
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);

  // All ring vertices on top of each other: uniform, not NaN.
  std::vector<Vec3> z = {Vec3::Zero(), Vec3(1, 0, 0), Vec3(1, 0, 0), Vec3(1, 0, 0)};
  for (double w : ring_weights(z[0], std::vector<Index>{1, 2, 3}, z, true)) EXPECT_NEAR(w, 1.0 / 3.0, 1e-12);
}

TEST(RingFrame, OffsetIsInvariantUnderRotationTranslationAndScale) {
  std::vector<Vec3> x = {Vec3(0.1, 0.05, 0.3)};
  std::vector<Index> ring;
  for (int i = 0; i < 7; ++i) {
    const double a = i * 2 * std::numbers::pi / 7;
    x.emplace_back(std::cos(a) * (1 + 0.2 * i), std::sin(a), 0.1 * (i % 3));
    ring.push_back(static_cast<Index>(i + 1));
  }
  const auto w = ring_weights(x[0], ring, x, true);
  const Vec3 local = ring_frame(ring, w, x, true).to_local(x[0]);

  const Eigen::Matrix3d r = Eigen::AngleAxisd(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  std::vector<Vec3> moved;
  for (const Vec3& p : x) moved.push_back(2.5 * (r * p) + Vec3(4, -1, 7));
  const RingFrame f2 = ring_frame(ring, w, moved, true);
  EXPECT_LT((f2.to_local(moved[0]) - local).norm(), 1e-12);
  EXPECT_LT((f2.from_local(local) - moved[0]).norm(), 1e-12);
  EXPECT_NEAR(f2.axes.determinant(), 1.0, 1e-12);
}

TEST(CotangentLaplacian, FlatInteriorIsZeroAndWeightsAreClamped) {
  const TriMesh grid = [] {
    TriMesh m = test::wavy_grid(8);
    for (Vec3& p : m.positions) p.z() = 0.0;
    return m;
  }();
  const CotangentLaplacian L = cotangent_laplacian(grid);
  const auto delta = L.apply(grid.positions);
  for (int i = 1; i < 8; ++i)
    for (int j = 1; j < 8; ++j) EXPECT_LT(delta[i * 9 + j].norm(), 1e-12);
  for (double w : L.weights) {
    EXPECT_GE(w, CotangentLaplacian::kMinWeight);
    EXPECT_LE(w, CotangentLaplacian::kMaxWeight);
  }

  // A sliver: finite weights, finite δ.
  TriMesh sliver;
  sliver.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0.5, 1e-13, 0), Vec3(0.5, 1, 0)};
  sliver.faces = {{0, 1, 2}, {0, 3, 1}};
  const CotangentLaplacian S = cotangent_laplacian(sliver);
  for (const Vec3& d : S.apply(sliver.positions)) EXPECT_TRUE(d.allFinite());
}

// The plain definition, kept as the reference: every corner's half
// cotangent added to its opposite edge in both rows, face by face, then
// clamped. Same additions in the same order, so the same bits.
CotangentLaplacian reference_cotangent_laplacian(const TriMesh& mesh) {
  std::vector<std::map<Index, double>> rows(mesh.positions.size());
  for (const Triangle& f : mesh.faces)
    for (int c = 0; c < 3; ++c) {
      const Index a = f[c], b = f[(c + 1) % 3], d = f[(c + 2) % 3];
      const double half_cot = 0.5 * cotangent_at(mesh.positions[a], mesh.positions[b], mesh.positions[d]);
      rows[b][d] += half_cot;
      rows[d][b] += half_cot;
    }
  CotangentLaplacian L;
  L.offsets.push_back(0);
  for (const auto& row : rows) {
    for (const auto& [to, w] : row) {
      L.neighbors.push_back(to);
      L.weights.push_back(std::clamp(w, CotangentLaplacian::kMinWeight, CotangentLaplacian::kMaxWeight));
    }
    L.offsets.push_back(static_cast<Index>(L.neighbors.size()));
  }
  return L;
}

TEST(CotangentLaplacian, EqualsThePlainDefinitionBitForBit) {
  TriMesh degenerate = test::wavy_grid(6);
  degenerate.faces.push_back({3, 3, 10});  // a vertex twice in one face
  degenerate.faces.push_back({3, 10, 4});  // an edge in three faces
  // (The 41k sphere's rows are built in ranges on 3 threads, then joined.)
  for (const TriMesh& mesh : {test::wavy_grid(12), test::torus(10, 7), test::two_spheres(2), test::shipped_mesh("head_open.off"),
                              degenerate, test::icosphere(6)}) {
    const CotangentLaplacian R = reference_cotangent_laplacian(mesh);
    for (const int threads : {1, 3}) {
      const CotangentLaplacian L = cotangent_laplacian(mesh, threads);
      EXPECT_EQ(L.offsets, R.offsets) << threads << " threads";
      EXPECT_EQ(L.neighbors, R.neighbors) << threads << " threads";
      ASSERT_EQ(L.weights.size(), R.weights.size());
      for (std::size_t k = 0; k < L.weights.size(); ++k)
        ASSERT_EQ(std::bit_cast<std::uint64_t>(L.weights[k]), std::bit_cast<std::uint64_t>(R.weights[k])) << k;
    }
  }
}

TEST(TriangleGeometry, QualityAndCotangent) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0.5, std::sqrt(3.0) / 2, 0);
  EXPECT_NEAR(triangle_quality(a, b, c), 1.0, 1e-12);
  EXPECT_NEAR(triangle_quality(a, b, Vec3(2, 0, 0)), 0.0, 1e-12);
  EXPECT_NEAR(cotangent_at(a, b, c), 1.0 / std::sqrt(3.0), 1e-12);
  EXPECT_TRUE(std::isfinite(cotangent_at(a, b, Vec3(2, 0, 0))));
}

}  // namespace
}  // namespace filigree
