#pragma once
// The animation the runtime benchmarks play for every T: the motion ramps in
// over kRampFrames frames, then kTimedFrames timed frames go once round an
// oscillation (0.8 … 1) that ends at full strength, so the cut update works
// as it does in use. Quality is measured on the last timed frame, at phase 1.

#include <cmath>
#include <numbers>

#include "hierarchy/hierarchy.h"
#include "runtime/pose.h"
#include "runtime/procedural_motion.h"

namespace filigree::bench {

constexpr int kRampFrames = 8;
constexpr int kTimedFrames = 12;
constexpr int kLastFrame = kRampFrames + kTimedFrames - 1;  // the quality frame

// The motion's phase at a frame: the last timed frame is at phase 1, so its
// truth is the field at full strength (a truth should still take
// phase_of(kLastFrame), whatever it is).
inline double phase_of(int frame) {
  if (frame < kRampFrames) return static_cast<double>(frame + 1) / kRampFrames;
  return 0.9 + 0.1 * std::cos(2.0 * std::numbers::pi * (frame - kRampFrames) / (kTimedFrames - 1));
}

// The base vertices are original vertices: the pose is the field on their
// rest positions, in base order (so it is exactly the truth there).
inline Pose base_pose(const Hierarchy& h, const MotionField& field) {
  Pose pose;
  pose.positions.reserve(h.base_vertices.size());
  for (Index v : h.base_vertices) pose.positions.push_back(field(h.rest_positions[v]));
  return pose;
}

}  // namespace filigree::bench
