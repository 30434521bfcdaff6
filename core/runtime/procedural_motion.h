#pragma once
// Procedural motions for demos, tests and benchmarks. A motion is a map of
// space (MotionField), so the same map can pose the base vertices and give the
// *truth* on every vertex of the detailed mesh, which is what quality is
// measured against (DESIGN §2.3, issue 10 item 6).

#include <optional>
#include <span>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"
#include "runtime/pose.h"

namespace filigree {

// s below runs −1 … 1 along the longest bbox axis a of the reference points;
// b is the next longest axis and c the third.
enum class Motion {
  kBend,   // the half beyond the middle of the longest axis curls by up to 60° about c
  kTwist,  // twist about the longest axis, ±45° at its ends
  kWave,   // a travelling wave across the longest axis, 3% of the diagonal
  kBump,   // a local bump: points near the reference's extreme point along +b pushed out by 5% of the diagonal
  kFold,   // a sharp fold: 90° about c within the middle half of the longest axis (s in [−½, ½])
  kTwist360,  // the twist of kTwist, ±180° at the ends: a full turn end to end
};

std::optional<Motion> parse_motion(const std::string& name);  // "bend", "twist", "wave", "bump", "fold", "twist360"
const char* to_string(Motion m);

// Where a motion happens: the bounding box of the reference points and what is
// derived from it once.
struct MotionFrame {
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero(), center = Vec3::Zero();
  int a = 0, b = 1, c = 2;  // axes by extent: longest, next, the rest
  double half = 1.0;        // half the extent along a (s = (p[a] − center[a]) / half)
  double diagonal = 0.0;    // of the bbox
  Vec3 bump_center = Vec3::Zero();  // the first reference point with the largest p[b]
};

// A motion as a map R³ → R³ at one phase, its frame taken from `reference`
// points. Every motion is a function of position only (never of a point's
// index), so applying the field to a subset of the reference, or to points that
// are not in it, is consistent with applying it to the whole. No reference
// points: the identity.
class MotionField {
 public:
  MotionField(std::span<const Vec3> reference, Motion motion, double phase);

  Vec3 operator()(const Vec3& p) const;
  std::vector<Vec3> apply(std::span<const Vec3> points) const;
  // The same motion and frame at another phase (the frame costs a pass over the
  // reference; this does not).
  MotionField with_phase(double phase) const;

  Motion motion() const { return motion_; }
  double phase() const { return phase_; }
  const MotionFrame& frame() const { return frame_; }

 private:
  Vec3 fold(const Vec3& p) const;

  Motion motion_ = Motion::kBend;
  double phase_ = 0.0;
  bool identity_ = true;
  MotionFrame frame_;
  Eigen::Vector2d fold_end_ = Eigen::Vector2d::Zero();  // the fold's fibre offset at the band's end, for this phase
};

// The base rest positions moved by `motion` at `phase` in [0, 1] (0 = rest):
// MotionField(base_rest, motion, phase) applied to each of them.
Pose procedural_pose(const std::vector<Vec3>& base_rest, Motion motion, double phase);

}  // namespace filigree
