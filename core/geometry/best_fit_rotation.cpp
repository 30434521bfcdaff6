#include "geometry/best_fit_rotation.h"

#include <Eigen/LU>
#include <Eigen/SVD>

namespace filigree {

Eigen::Matrix3d best_fit_rotation(const Eigen::Matrix3d& covariance) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixV() * svd.matrixU().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixV() * d * svd.matrixU().transpose();
}

}  // namespace filigree
