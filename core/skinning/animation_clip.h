#pragma once
// Sampling an animation clip at a time: the joints' local transforms it sets.
//
// Interpolation follows the glTF 2.0 specification, Appendix C
// ("Animation Sampler Interpolation Modes"):
//  - STEP: the value of the last key at or before t.
//  - LINEAR: v_k + s·(v_{k+1} − v_k) with s = (t − t_k) / (t_{k+1} − t_k);
//    rotations take the shortest-path spherical linear interpolation (q and
//    −q are the same rotation; the path never goes the long way round).
//  - CUBICSPLINE: each key stores in-tangent a, value v, out-tangent b, in
//    that order ([a_k, v_k, b_k] per key); with td = t_{k+1} − t_k,
//      p(s) = (2s³ − 3s² + 1)·v_k + (s³ − 2s² + s)·td·b_k
//           + (−2s³ + 3s²)·v_{k+1} + (s³ − s²)·td·a_{k+1},
//    component-wise, rotations normalised afterwards.
// Before the first key a channel holds the first key's value, after the last
// the last key's value (tangents play no part there).
// Rotations are stored x y z w, glTF's order.

#include <vector>

#include "skinning/rig.h"

namespace filigree {

// Overwrites, in `local` (one entry per joint, indexed by ClipChannel::joint),
// exactly the properties the clip's channels animate, with their values at
// clip time t (seconds); everything else in `local` is left as it was. Keys
// are found by binary search: O(channels · log keys).
// Throws RigError if a channel names a joint ≥ local.size() or its keys are
// malformed (no keys, or a value count that does not match the key count):
// a clip that passed validate_rig never throws for the second reason.
// A rotation that comes out degenerate (all-zero keys) is the identity.
void sample_clip(const AnimationClip& clip, double t, std::vector<JointTransform>& local);

}  // namespace filigree
