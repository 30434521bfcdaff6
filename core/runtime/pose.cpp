#include "runtime/pose.h"

#include <string>

namespace filigree {

void validate_pose(const Pose& pose, std::size_t base_vertex_count) {
  if (pose.positions.size() != base_vertex_count)
    throw PoseError("pose has " + std::to_string(pose.positions.size()) + " positions, the base mesh has " +
                    std::to_string(base_vertex_count) + " vertices");
  for (std::size_t i = 0; i < pose.positions.size(); ++i)
    if (!pose.positions[i].allFinite())
      throw PoseError("pose position " + std::to_string(i) + " is not finite (NaN or Inf)");
}

}  // namespace filigree
