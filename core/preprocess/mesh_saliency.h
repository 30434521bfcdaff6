#pragma once
// Mesh saliency (Lee, Varshney, Jacobs 2005): how much a vertex's mean
// curvature stands out from its surroundings, across scales.

#include <atomic>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// Saliency in [0, 1] per vertex: for σ ∈ {2,3,4,5,6}·ε (ε = 0.3% of the
// bounding-box diagonal), |G(H,σ) − G(H,2σ)| with G the Gaussian-weighted
// average of mean curvature within 2σ; each scale's map is normalised by its
// maximum, the maps are summed and the sum normalised to [0, 1].
// Deviation from the paper, for speed on million-vertex meshes: G is evaluated
// on area-weighted clusters of a 2ε grid instead of on every vertex, and each
// vertex takes its cluster's value; the paper's local-maxima suppression is
// replaced by the plain max normalisation.
// When `stop` turns true the clusters left are skipped and the result is
// meaningless: the caller, which set it, throws it away.
std::vector<double> mesh_saliency(const TriMesh& mesh, const std::vector<double>& mean_curvature, int threads,
                                  const std::atomic<bool>* stop = nullptr);

}  // namespace filigree
