#pragma once
// Weights of a vertex's 1-ring for direct recovery (thesis eq. 3.3, 3.10).

#include <span>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

// Normalised (Σ = 1, all > 0) weights of the ring vertices around `center`.
// The ring is ordered so that (center, ring[k], ring[k+1]) are the faces; it is
// `closed` for an interior vertex (last → first is a face too) and open for a
// boundary vertex. Cotangent weights are used when every one is safely
// positive; on an obtuse or degenerate fan they fall back to mean-value weights
// (Floater 2003), which stay positive for any fan with angles below π, and to
// uniform weights if even those degenerate. Never divides by a near-zero sum.
std::vector<double> ring_weights(const Vec3& center, std::span<const Index> ring, std::span<const Vec3> positions,
                                 bool closed);

}  // namespace filigree
