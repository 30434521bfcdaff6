#pragma once
// The rotation that best maps one set of edge vectors onto another (Kabsch).

#include <Eigen/Core>

namespace filigree {

// For the covariance S = Σ w · e_rest · e_posedᵀ, the proper rotation R
// minimising Σ w‖R e_rest − e_posed‖²: R = V · diag(1, 1, det(V Uᵀ)) · Uᵀ
// with S = U Σ Vᵀ. Rank-deficient S (a flat ring) still gives a rotation.
Eigen::Matrix3d best_fit_rotation(const Eigen::Matrix3d& covariance);

}  // namespace filigree
