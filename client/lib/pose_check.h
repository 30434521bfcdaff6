#pragma once
// What a Driver checks of a pose before it sends it, so that a bad pose is
// an error of that send (std::invalid_argument naming the value), not one
// the server answers by ending the stream. Sizes against the session's mesh
// are the caller's to check (the C API and Python do); these need no mesh.

#include <cstdint>
#include <span>
#include <string>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

// Every coordinate finite. `indices` (may be empty: a full pose) names the
// base vertex of each triple in the message. Throws std::invalid_argument.
void check_positions(const char* function, std::span<const std::uint32_t> indices, std::span<const float> positions);

// Every value finite, every local rotation a non-zero quaternion, every
// model matrix affine. `joints` (may be empty: every joint in order) names
// the joint of each group of values, and errors name that joint, not the
// group's place in the message. Throws std::invalid_argument.
void check_joints(const char* function, v1::JointPose::Space space, std::span<const std::uint32_t> joints,
                  std::span<const float> values);

}  // namespace filigree
