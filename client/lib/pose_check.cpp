#include "pose_check.h"

#include <cmath>
#include <stdexcept>

namespace filigree {

void check_positions(const char* function, std::span<const std::uint32_t> indices, std::span<const float> positions) {
  static const char* const kAxis[] = {"x", "y", "z"};
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!std::isfinite(positions[i])) {
      const std::size_t entry = i / 3;
      const std::size_t vertex = indices.empty() ? entry : indices[entry];
      throw std::invalid_argument(std::string(function) + ": base vertex " + std::to_string(vertex) + "'s " + kAxis[i % 3] +
                                  " is not finite (NaN or Inf)");
    }
}

void check_joints(const char* function, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                  std::span<const float> values) {
  const bool model = space == v1::JointPose::SPACE_MODEL_MATRIX;
  const std::size_t per = model ? 16 : 10;
  for (std::size_t entry = 0; entry * per < values.size(); ++entry) {
    const std::size_t joint = joints.empty() ? entry : joints[entry];
    const std::span<const float> v = values.subspan(entry * per, std::min(per, values.size() - entry * per));
    const auto name = [&] { return std::string(function) + ": joint " + std::to_string(joint); };
    for (const float x : v)
      if (!std::isfinite(x)) throw std::invalid_argument(name() + " has a value that is not finite (NaN or Inf)");
    if (v.size() < per) return;  // a short pose: the size check is the caller's
    if (model) {
      // Column-major: the last row is entries 3, 7, 11, 15.
      if (v[3] != 0.0f || v[7] != 0.0f || v[11] != 0.0f || v[15] != 1.0f)
        throw std::invalid_argument(name() + "'s matrix is not affine (its last row must be 0 0 0 1)");
    } else {
      const double norm = std::sqrt(double(v[3]) * v[3] + double(v[4]) * v[4] + double(v[5]) * v[5] + double(v[6]) * v[6]);
      if (!(norm > 1e-6)) throw std::invalid_argument(name() + " has a zero rotation quaternion");
    }
  }
}

}  // namespace filigree
