#include "runtime/rotation_interpolation.h"

namespace filigree {

Eigen::Quaterniond interpolate_rotation(const std::array<Eigen::Quaterniond, 3>& q, const Vec3& bary) {
  int lead = 0;
  bary.maxCoeff(&lead);
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  for (int c = 0; c < 3; ++c) {
    const double sign = q[c].coeffs().dot(q[lead].coeffs()) < 0.0 ? -1.0 : 1.0;
    sum += bary[c] * sign * q[c].coeffs();
  }
  const double norm = sum.norm();
  if (!(norm > 1e-12)) return q[lead];
  Eigen::Quaterniond out;
  out.coeffs() = sum / norm;
  return out;
}

}  // namespace filigree
