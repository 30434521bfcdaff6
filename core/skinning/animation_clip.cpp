#include "skinning/animation_clip.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace filigree {
namespace {

using Vec4 = Eigen::Vector4d;

// Where t falls among a channel's keys: key k and the fraction s of the way
// to key k + 1. `between` is false when t is at or outside a key (s = 0), so
// key k + 1 is never read past the last key.
struct KeySpan {
  std::size_t k = 0;
  double s = 0;
  double td = 0;
  bool between = false;
};

KeySpan locate(const std::vector<float>& times, double t) {
  const std::size_t n = times.size();
  KeySpan span;
  if (t <= times.front()) return span;
  if (t >= times.back()) {
    span.k = n - 1;
    return span;
  }
  // times[k] ≤ t < times[k + 1]; t is strictly inside, so 0 < it < n.
  const auto it = std::upper_bound(times.begin(), times.end(), t, [](double a, float b) { return a < static_cast<double>(b); });
  span.k = static_cast<std::size_t>(it - times.begin()) - 1;
  span.td = static_cast<double>(times[span.k + 1]) - static_cast<double>(times[span.k]);
  span.s = (t - static_cast<double>(times[span.k])) / span.td;
  if (span.s > 0) span.between = true;
  return span;
}

// The `width` floats at values[key · stride + offset].
Vec4 read(const ClipChannel& ch, std::size_t width, std::size_t stride, std::size_t offset, std::size_t key) {
  Vec4 v = Vec4::Zero();
  const float* p = ch.values.data() + key * stride + offset;
  for (std::size_t i = 0; i < width; ++i) v[static_cast<Eigen::Index>(i)] = p[i];
  return v;
}

// Stored x y z w; Eigen's constructor takes w first.
Eigen::Quaterniond to_quaternion(const Vec4& v) { return Eigen::Quaterniond(v[3], v[0], v[1], v[2]); }

Eigen::Quaterniond unit_or_identity(const Eigen::Quaterniond& q) {
  const double n = q.norm();
  if (!(n > 0) || !std::isfinite(n)) return Eigen::Quaterniond::Identity();
  return Eigen::Quaterniond(q.coeffs() / n);
}

// The channel's value at t, in the first `width` components.
Vec4 sample_channel(const ClipChannel& ch, std::size_t width, double t) {
  const KeySpan at = locate(ch.times, t);
  const bool rotation = ch.path == ClipChannel::Path::kRotation;
  switch (ch.interpolation) {
    case ClipChannel::Interpolation::kStep: return read(ch, width, width, 0, at.k);
    case ClipChannel::Interpolation::kLinear: {
      const Vec4 v0 = read(ch, width, width, 0, at.k);
      if (!at.between) return v0;
      const Vec4 v1 = read(ch, width, width, 0, at.k + 1);
      if (!rotation) return v0 + at.s * (v1 - v0);
      // Eigen's slerp flips the sign of the second key when the dot product
      // is negative: the shortest path glTF asks for.
      const Eigen::Quaterniond q = unit_or_identity(to_quaternion(v0)).slerp(at.s, unit_or_identity(to_quaternion(v1)));
      return q.coeffs();  // x y z w, like the stored keys
    }
    case ClipChannel::Interpolation::kCubicSpline: {
      const std::size_t stride = 3 * width;
      const Vec4 v0 = read(ch, width, stride, width, at.k);
      if (!at.between) return v0;
      const Vec4 b0 = read(ch, width, stride, 2 * width, at.k);
      const Vec4 a1 = read(ch, width, stride, 0, at.k + 1);
      const Vec4 v1 = read(ch, width, stride, width, at.k + 1);
      const double s = at.s, s2 = s * s, s3 = s2 * s;
      return (2 * s3 - 3 * s2 + 1) * v0 + (s3 - 2 * s2 + s) * at.td * b0 + (-2 * s3 + 3 * s2) * v1 + (s3 - s2) * at.td * a1;
    }
  }
  throw RigError("sample_clip: unknown interpolation " + std::to_string(static_cast<int>(ch.interpolation)));
}

}  // namespace

void sample_clip(const AnimationClip& clip, double t, std::vector<JointTransform>& local) {
  if (std::isnan(t)) throw RigError("sample_clip: clip '" + clip.name + "' sampled at a NaN time");
  for (std::size_t c = 0; c < clip.channels.size(); ++c) {
    const ClipChannel& ch = clip.channels[c];
    // The message is built only on failure: this runs for every channel of every sample.
    const auto where = [&] { return "sample_clip: clip '" + clip.name + "' channel " + std::to_string(c); };
    if (ch.joint >= local.size())
      throw RigError(where() + ": joint " + std::to_string(ch.joint) + ", but there are " + std::to_string(local.size()) + " local transforms");
    std::size_t width = 0;
    switch (ch.path) {
      case ClipChannel::Path::kTranslation:
      case ClipChannel::Path::kScale: width = 3; break;
      case ClipChannel::Path::kRotation: width = 4; break;
      default: throw RigError(where() + ": unknown path " + std::to_string(static_cast<int>(ch.path)));
    }
    // Checked here, not left to validate_rig: a wrong count would read past
    // the values.
    const std::size_t per_key = ch.interpolation == ClipChannel::Interpolation::kCubicSpline ? 3 * width : width;
    if (ch.times.empty() || ch.values.size() != ch.times.size() * per_key)
      throw RigError(where() + ": " + std::to_string(ch.values.size()) + " values for " + std::to_string(ch.times.size()) + " keys");

    const Vec4 v = sample_channel(ch, width, t);
    JointTransform& target = local[ch.joint];
    switch (ch.path) {
      case ClipChannel::Path::kTranslation: target.translation = v.head<3>(); break;
      case ClipChannel::Path::kScale: target.scale = v.head<3>(); break;
      case ClipChannel::Path::kRotation: target.rotation = unit_or_identity(to_quaternion(v)); break;
    }
  }
}

}  // namespace filigree
