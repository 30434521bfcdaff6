#pragma once
// Discrete mean curvature (Meyer et al. 2002, the operator the thesis cites).

#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct CotangentLaplacian;

// |H_i| = |Σ_j w_ij (x_i − x_j)| / (2·A_i), with the cotangent weights of
// `laplacian` (w = (cot α + cot β)/2) and A_i one third of the incident
// triangle areas. Boundary vertices and vertices of zero area get 0.
// `is_boundary[i]` marks vertices on a boundary edge.
std::vector<double> mean_curvature(const TriMesh& mesh, const CotangentLaplacian& laplacian,
                                   const std::vector<bool>& is_boundary);

}  // namespace filigree
