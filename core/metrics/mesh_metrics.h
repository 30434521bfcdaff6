#pragma once
// How far a deformation result is from a reference deformation of the same
// mesh: the PolyMeCo-style metrics of thesis §4.1.1 (geometric distance, normal
// deviation, curvature deviation; Silva et al. 2005), restricted to meshes whose
// vertices correspond by index, which is what two deformations of one mesh are.
// DESIGN §2.3: the reference is the whole-mesh optimization of the same pose.

#include <cstddef>
#include <string>

#include "mesh/tri_mesh.h"

namespace filigree {

struct MeshComparison {
  std::size_t vertex_count = 0;
  // |result_i − reference_i| over all vertices, as fractions of the reference's
  // bounding-box diagonal.
  double rms_distance = 0.0;
  double max_distance = 0.0;
  // Angle in degrees between the area-weighted vertex normals of the two meshes,
  // over the vertices with a non-zero normal in both; p95 is the nearest-rank
  // 95th percentile.
  double mean_normal_deviation_deg = 0.0;
  double p95_normal_deviation_deg = 0.0;
  // Mean over interior vertices of |H_result − H_reference|, relative to the
  // mean |H_reference| there. H is the discrete mean curvature magnitude
  // |Σ_j w_ij (x_i − x_j)| / (2·A_i) with cotangent weights and A_i a third of
  // the incident triangle areas (preprocess/mean_curvature.h). Vertices on a
  // boundary edge or in no face are left out. The denominator is floored at
  // 1 / diagonal, the curvature of a sphere as large as the reference, so a
  // flat reference gives a finite value.
  double mean_curvature_deviation = 0.0;
};

// Compares `result` against `reference`, vertex i against vertex i. Both are
// measured with the reference's faces; `result.faces` must equal them or be
// empty (same connectivity). Throws std::invalid_argument if the vertex counts
// differ, the faces differ, a face index is out of range, a position is NaN/Inf,
// or the reference has no extent (zero bounding-box diagonal).
// Cost: linear in the mesh size, plus the sort in cotangent_laplacian().
MeshComparison compare_meshes(const TriMesh& result, const TriMesh& reference);

// One JSON object on one line, keys named as the fields, numbers with 9
// significant digits.
std::string to_json(const MeshComparison& comparison);

}  // namespace filigree
