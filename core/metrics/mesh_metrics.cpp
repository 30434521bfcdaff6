#include "metrics/mesh_metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <stdexcept>
#include <vector>

#include <Eigen/Geometry>

#include "geometry/cotangent_laplacian.h"
#include "geometry/triangle_geometry.h"
#include "preprocess/mean_curvature.h"

namespace filigree {
namespace {

[[noreturn]] void fail(const std::string& reason) { throw std::invalid_argument("compare: " + reason); }

void check_positions(const std::vector<Vec3>& positions, const char* which) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!positions[i].allFinite()) fail(std::string(which) + " vertex " + std::to_string(i) + " is not finite (NaN or Inf)");
}

void check_inputs(const TriMesh& result, const TriMesh& reference) {
  const std::size_t n = reference.vertex_count();
  if (result.vertex_count() != n)
    fail("the result has " + std::to_string(result.vertex_count()) + " vertices, the reference has " + std::to_string(n) +
         "; vertices must correspond by index");
  if (!result.faces.empty() && result.faces != reference.faces) {
    if (result.face_count() != reference.face_count())
      fail("the result has " + std::to_string(result.face_count()) + " faces, the reference has " +
           std::to_string(reference.face_count()) + "; both must have the same connectivity");
    const auto first = std::mismatch(result.faces.begin(), result.faces.end(), reference.faces.begin()).first;
    fail("face " + std::to_string(first - result.faces.begin()) +
         " differs between the result and the reference; both must have the same connectivity");
  }
  if (n == 0) fail("the meshes have no vertices");
  check_positions(result.positions, "result");
  check_positions(reference.positions, "reference");
  for (std::size_t k = 0; k < reference.face_count(); ++k)
    for (const Index v : reference.faces[k])
      if (v >= n) fail("reference face " + std::to_string(k) + " uses vertex " + std::to_string(v) + " of " + std::to_string(n));
}

// Σ of the incident triangles' area vectors: the area-weighted normal, unnormalised.
std::vector<Vec3> vertex_normals(const std::vector<Vec3>& x, const std::vector<Triangle>& faces) {
  std::vector<Vec3> normals(x.size(), Vec3::Zero());
  for (const Triangle& f : faces) {
    const Vec3 a = triangle_area_vector(x[f[0]], x[f[1]], x[f[2]]);
    for (const Index v : f) normals[v] += a;
  }
  return normals;
}

// A vertex is on the boundary when one of its edges lies in a single face. The
// Laplacian lists each vertex's neighbours once and sorted, so its entries
// index the edges and counting faces per edge needs no hash or global sort.
std::vector<bool> boundary_vertices(const std::vector<Triangle>& faces, const CotangentLaplacian& L) {
  std::vector<Index> faces_per_entry(L.neighbors.size(), 0);
  auto count = [&](Index from, Index to) {
    const auto row = L.neighbors.begin() + L.offsets[from], row_end = L.neighbors.begin() + L.offsets[from + 1];
    ++faces_per_entry[std::lower_bound(row, row_end, to) - L.neighbors.begin()];
  };
  for (const Triangle& f : faces)
    for (int c = 0; c < 3; ++c) {
      count(f[c], f[(c + 1) % 3]);
      count(f[(c + 1) % 3], f[c]);
    }
  std::vector<bool> boundary(L.vertex_count(), false);
  for (std::size_t i = 0; i < L.vertex_count(); ++i)
    for (Index k = L.offsets[i]; k < L.offsets[i + 1]; ++k)
      if (faces_per_entry[k] == 1) boundary[i] = true;
  return boundary;
}

// Nearest-rank percentile; reorders `values`.
double percentile(std::vector<double>& values, double fraction) {
  if (values.empty()) return 0.0;
  const auto rank = static_cast<std::size_t>(std::ceil(fraction * static_cast<double>(values.size())));
  const auto nth = values.begin() + static_cast<std::ptrdiff_t>(std::max<std::size_t>(rank, 1) - 1);
  std::nth_element(values.begin(), nth, values.end());
  return *nth;
}

void measure_distances(const TriMesh& result, const TriMesh& reference, double diagonal, MeshComparison& out) {
  double sum_squared = 0.0, max_squared = 0.0;
  for (std::size_t i = 0; i < reference.vertex_count(); ++i) {
    const double d2 = (result.positions[i] - reference.positions[i]).squaredNorm();
    sum_squared += d2;
    max_squared = std::max(max_squared, d2);
  }
  out.rms_distance = std::sqrt(sum_squared / static_cast<double>(reference.vertex_count())) / diagonal;
  out.max_distance = std::sqrt(max_squared) / diagonal;
}

void measure_normals(const TriMesh& result, const TriMesh& reference, MeshComparison& out) {
  const std::vector<Vec3> a = vertex_normals(result.positions, reference.faces);
  const std::vector<Vec3> b = vertex_normals(reference.positions, reference.faces);
  std::vector<double> degrees;
  degrees.reserve(a.size());
  double sum = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a[i].squaredNorm() == 0.0 || b[i].squaredNorm() == 0.0) continue;
    // atan2 keeps small angles exact where acos of a dot product would not.
    const double deg = std::atan2(a[i].cross(b[i]).norm(), a[i].dot(b[i])) * (180.0 / std::numbers::pi);
    degrees.push_back(deg);
    sum += deg;
  }
  out.mean_normal_deviation_deg = degrees.empty() ? 0.0 : sum / static_cast<double>(degrees.size());
  out.p95_normal_deviation_deg = percentile(degrees, 0.95);
}

void measure_curvature(const TriMesh& result, const TriMesh& reference, double diagonal, MeshComparison& out) {
  const TriMesh measured{result.positions, reference.faces};
  const CotangentLaplacian l_reference = cotangent_laplacian(reference);
  const std::vector<bool> boundary = boundary_vertices(reference.faces, l_reference);
  const std::vector<double> h_reference = mean_curvature(reference, l_reference, boundary);
  const std::vector<double> h_result = mean_curvature(measured, cotangent_laplacian(measured), boundary);

  std::vector<bool> in_face(reference.vertex_count(), false);
  for (const Triangle& f : reference.faces)
    for (const Index v : f) in_face[v] = true;
  double sum_difference = 0.0, sum_reference = 0.0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < reference.vertex_count(); ++i) {
    if (boundary[i] || !in_face[i]) continue;
    sum_difference += std::abs(h_result[i] - h_reference[i]);
    sum_reference += h_reference[i];
    ++count;
  }
  if (count == 0) return;
  const double mean_reference = std::max(sum_reference / static_cast<double>(count), 1.0 / diagonal);
  out.mean_curvature_deviation = sum_difference / static_cast<double>(count) / mean_reference;
}

// JSON has no NaN or Inf.
std::string json_number(double value) {
  if (!std::isfinite(value)) return "null";
  char text[32];
  std::snprintf(text, sizeof text, "%.9g", value);
  return text;
}

}  // namespace

MeshComparison compare_meshes(const TriMesh& result, const TriMesh& reference) {
  check_inputs(result, reference);
  const double diagonal = bounding_box_diagonal(reference.positions);
  if (diagonal == 0.0) fail("the reference has no extent (all its vertices coincide)");
  MeshComparison out;
  out.vertex_count = reference.vertex_count();
  measure_distances(result, reference, diagonal, out);
  measure_normals(result, reference, out);
  measure_curvature(result, reference, diagonal, out);
  return out;
}

std::string to_json(const MeshComparison& c) {
  return "{\"vertex_count\": " + std::to_string(c.vertex_count) +
         ", \"rms_distance\": " + json_number(c.rms_distance) +
         ", \"max_distance\": " + json_number(c.max_distance) +
         ", \"mean_normal_deviation_deg\": " + json_number(c.mean_normal_deviation_deg) +
         ", \"p95_normal_deviation_deg\": " + json_number(c.p95_normal_deviation_deg) +
         ", \"mean_curvature_deviation\": " + json_number(c.mean_curvature_deviation) + "}";
}

}  // namespace filigree
