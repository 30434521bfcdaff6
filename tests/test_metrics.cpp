// The quality metrics of DESIGN §2.3 on cases whose answer is known exactly.

#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "metrics/mesh_metrics.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// A flat n×n grid in the z = 0 plane: every vertex normal is +z.
TriMesh flat_grid(int n) {
  TriMesh m = test::wavy_grid(n);
  for (Vec3& p : m.positions) p.z() = 0.0;
  return m;
}

TriMesh transformed(TriMesh m, const Eigen::Affine3d& t) {
  for (Vec3& p : m.positions) p = t * p;
  return m;
}

template <typename F>
std::string message_of(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "(no exception)";
}

TEST(MeshMetrics, IdenticalMeshesGiveZeros) {
  const TriMesh sphere = test::icosphere(3);
  const MeshComparison c = compare_meshes(sphere, sphere);
  EXPECT_EQ(c.vertex_count, sphere.vertex_count());
  EXPECT_EQ(c.rms_distance, 0.0);
  EXPECT_EQ(c.max_distance, 0.0);
  EXPECT_EQ(c.mean_normal_deviation_deg, 0.0);
  EXPECT_EQ(c.p95_normal_deviation_deg, 0.0);
  EXPECT_EQ(c.mean_curvature_deviation, 0.0);
}

TEST(MeshMetrics, EmptyResultFacesMeanSameConnectivity) {
  const TriMesh sphere = test::icosphere(2);
  TriMesh moved = transformed(sphere, Eigen::Affine3d(Eigen::Scaling(1.5)));
  const MeshComparison with_faces = compare_meshes(moved, sphere);
  moved.faces.clear();
  const MeshComparison without_faces = compare_meshes(moved, sphere);
  EXPECT_EQ(to_json(with_faces), to_json(without_faces));
}

TEST(MeshMetrics, TranslationIsDistanceOnly) {
  const TriMesh torus = test::torus(24, 12);
  const Vec3 d(0.03, -0.02, 0.01);
  const MeshComparison c = compare_meshes(transformed(torus, Eigen::Affine3d(Eigen::Translation3d(d))), torus);
  const double expected = d.norm() / bounding_box_diagonal(torus.positions);
  EXPECT_NEAR(c.rms_distance, expected, 1e-12);
  EXPECT_NEAR(c.max_distance, expected, 1e-12);
  EXPECT_NEAR(c.mean_normal_deviation_deg, 0.0, 1e-9);
  EXPECT_NEAR(c.p95_normal_deviation_deg, 0.0, 1e-9);
  EXPECT_NEAR(c.mean_curvature_deviation, 0.0, 1e-9);
}

TEST(MeshMetrics, RotationTurnsEveryNormalByTheAngle) {
  // Rotating about an axis in the grid's plane turns each +z normal by exactly the angle.
  const TriMesh grid = flat_grid(12);
  const double degrees = 30.0;
  const Eigen::AngleAxisd rotation(degrees * std::numbers::pi / 180.0, Vec3(1, 1, 0).normalized());
  const MeshComparison c = compare_meshes(transformed(grid, Eigen::Affine3d(rotation)), grid);
  EXPECT_NEAR(c.mean_normal_deviation_deg, degrees, 1e-9);
  EXPECT_NEAR(c.p95_normal_deviation_deg, degrees, 1e-9);
  EXPECT_GT(c.max_distance, 0.0);
  // Flat in both: no curvature to differ, and the flat reference gives no division by zero.
  EXPECT_NEAR(c.mean_curvature_deviation, 0.0, 1e-9);
}

TEST(MeshMetrics, OneMovedVertexSetsTheMaximum) {
  const TriMesh sphere = test::icosphere(3);
  TriMesh moved = sphere;
  const std::size_t v = 17;
  moved.positions[v] *= 1.1;
  const MeshComparison c = compare_meshes(moved, sphere);
  const double n = static_cast<double>(sphere.vertex_count());
  EXPECT_NEAR(c.max_distance, 0.1 / bounding_box_diagonal(sphere.positions), 1e-12);
  EXPECT_NEAR(c.rms_distance, c.max_distance / std::sqrt(n), 1e-12);
  // Only the moved vertex and its ring change their normals.
  EXPECT_GT(c.mean_normal_deviation_deg, 0.0);
  EXPECT_EQ(c.p95_normal_deviation_deg, 0.0);
}

TEST(MeshMetrics, CurvatureDeviationSeesBumps) {
  const TriMesh sphere = test::icosphere(4);
  TriMesh bumpy = sphere;
  for (Vec3& p : bumpy.positions) p *= 1.0 + 0.03 * std::sin(8 * p.x()) * std::sin(8 * p.y()) * std::sin(8 * p.z());
  const MeshComparison c = compare_meshes(bumpy, sphere);
  EXPECT_GT(c.mean_curvature_deviation, 0.1);
  EXPECT_GT(c.mean_normal_deviation_deg, 1.0);
  EXPECT_EQ(compare_meshes(bumpy, bumpy).mean_curvature_deviation, 0.0);
}

TEST(MeshMetrics, CurvatureDeviationIsRelative) {
  // Scaling by s divides every H by s: the relative deviation is 1 − 1/s at every vertex.
  const TriMesh sphere = test::icosphere(3);
  const MeshComparison c = compare_meshes(transformed(sphere, Eigen::Affine3d(Eigen::Scaling(2.0))), sphere);
  EXPECT_NEAR(c.mean_curvature_deviation, 0.5, 1e-9);
  EXPECT_NEAR(c.mean_normal_deviation_deg, 0.0, 1e-9);
}

TEST(MeshMetrics, BoundaryVerticesAreLeftOutOfCurvature) {
  // On a flat grid only the boundary vertices have a non-zero |Lx|; scaling the
  // grid would halve their H, yet the deviation must stay zero without them.
  const TriMesh grid = flat_grid(8);
  const MeshComparison c = compare_meshes(transformed(grid, Eigen::Affine3d(Eigen::Scaling(2.0))), grid);
  EXPECT_NEAR(c.mean_curvature_deviation, 0.0, 1e-9);
}

TEST(MeshMetrics, MismatchesAreErrors) {
  const TriMesh sphere = test::icosphere(1);
  TriMesh fewer = sphere;
  fewer.positions.pop_back();
  const std::string count = message_of([&] { compare_meshes(fewer, sphere); });
  EXPECT_NE(count.find("41 vertices"), std::string::npos) << count;
  EXPECT_NE(count.find("42"), std::string::npos) << count;

  TriMesh flipped = sphere;
  std::swap(flipped.faces[5][0], flipped.faces[5][1]);
  const std::string faces = message_of([&] { compare_meshes(flipped, sphere); });
  EXPECT_NE(faces.find("face 5"), std::string::npos) << faces;

  TriMesh nan = sphere;
  nan.positions[3].y() = std::nan("");
  const std::string finite = message_of([&] { compare_meshes(nan, sphere); });
  EXPECT_NE(finite.find("result vertex 3"), std::string::npos) << finite;

  TriMesh point = sphere;
  for (Vec3& p : point.positions) p = Vec3::Ones();
  EXPECT_THROW(compare_meshes(sphere, point), std::invalid_argument);
}

TEST(MeshMetrics, JsonHasEveryField) {
  MeshComparison c;
  c.vertex_count = 7;
  c.rms_distance = 0.125;
  c.max_distance = 1.0 / 3.0;
  c.mean_normal_deviation_deg = 2.5;
  c.p95_normal_deviation_deg = 4.0;
  c.mean_curvature_deviation = 1e-7;
  EXPECT_EQ(to_json(c),
            "{\"vertex_count\": 7, \"rms_distance\": 0.125, \"max_distance\": 0.333333333, "
            "\"mean_normal_deviation_deg\": 2.5, \"p95_normal_deviation_deg\": 4, \"mean_curvature_deviation\": 1e-07}");
}

}  // namespace
}  // namespace filigree
