#include "codec/frame_encoder.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "codec/delta_codec.h"
#include "codec/delta_staging.h"

namespace filigree {
namespace {

// Names the first implausible delta of a range (the check itself is branch-free).
[[noreturn]] void throw_bad_delta(const Vec3* pos, const Vec3* rest, std::size_t first, std::size_t count) {
  for (std::size_t i = 0; i < count; ++i)
    for (int k = 0; k < 3; ++k) check_delta(pos[i][k] - rest[i][k], first + i);
  throw std::logic_error("an implausible delta that is not there");
}

// Vertices per block of the staging pass: its per-coordinate masks stay in L1.
constexpr std::size_t kStageBlock = 512;

}  // namespace

FrameEncoder::FrameEncoder(std::span<const Vec3> rest, FrameEncoderOptions options) : rest_(rest), options_(options) {
  if (options_.chunk_vertices == 0) throw std::invalid_argument("frame chunks must hold at least one vertex");
  if (!is_encoding_speed(options_.speed))
    throw std::invalid_argument("Draco encoding speed must be 0…10, got " + std::to_string(options_.speed));
  if (options_.bits != 0 && (options_.bits < 8 || options_.bits > 24))
    throw std::invalid_argument("quantization bits must be 0 (automatic) or 8…24, got " + std::to_string(options_.bits));
  if (options_.bits == 0 && !(options_.max_error > 0.0 && std::isfinite(options_.max_error)))
    throw std::invalid_argument("automatic quantization needs a positive finite max_error");
  const std::size_t n = rest_.size();
  chunks_.resize(chunk_count(n, options_.chunk_vertices));
  for (std::size_t c = 0; c < chunks_.size(); ++c) {
    chunks_[c].out.first = static_cast<std::uint32_t>(c * options_.chunk_vertices);
    chunks_[c].out.count = static_cast<std::uint32_t>(std::min<std::size_t>(options_.chunk_vertices, n - c * options_.chunk_vertices));
  }
  keyframe_.assign(3 * n, 0.0f);
  decoded_.assign(3 * n, 0.0f);
}

void FrameEncoder::begin(bool force_keyframe) {
  force_ = force_keyframe || !have_keyframe_ || waste_ >= rest_.size();
}

void FrameEncoder::quantize_chunk(std::size_t c, std::span<const Vec3> positions) {
  Slot& slot = chunks_.at(c);
  EncodedChunk& out = slot.out;
  if (positions.size() != rest_.size())
    throw std::invalid_argument("frame has " + std::to_string(positions.size()) + " positions for " +
                                std::to_string(rest_.size()) + " vertices");
  const std::size_t a = out.first, count = out.count;
  // Unchanged means within what the keyframe already promised: the target
  // error (automatic bits), or the keyframe's own error (fixed bits).
  const double tolerance = options_.bits == 0 ? options_.max_error : keyframe_error_;

  // Pass 1: validate, stage the deltas in float32 (as Draco will store them),
  // and which vertices moved away from the keyframe (and, to know when a
  // fresh keyframe pays off, from the previous frame).
  slot.changed.assign(count, 1);
  if (options_.staging && slot.values.capacity() == 0) {
    slot.values = options_.staging->take(3 * count);
  } else {
    slot.values.resize(3 * count);
  }
  // One pass over the positions: the staged floats and, against the keyframe
  // and the previous frame, what moved. No branch per value (one flag for
  // the whole range): a bad delta is named afterwards, on the slow path.
  const Vec3* pos = positions.data() + a;
  const Vec3* rest = rest_.data() + a;
  float* staged = slot.values.data();
  const float* key = keyframe_.data() + 3 * a;
  const float* last = (previous_is_keyframe_ ? keyframe_ : decoded_).data() + 3 * a;
  std::uint8_t* flags = slot.changed.data();
  const bool compare = !force_;
  bool plausible = true;
  std::size_t changed = 0, moved_since_last = 0;
  std::uint8_t from_key[3 * kStageBlock], from_last[3 * kStageBlock];
  for (std::size_t b = 0; b < count; b += kStageBlock) {
    const std::size_t n = std::min(kStageBlock, count - b), o = 3 * b;
    if (!compare) {
      plausible &= stage_deltas(pos[b].data(), rest[b].data(), 3 * n, staged + o);
      continue;
    }
    plausible &= stage_and_compare_deltas(pos[b].data(), rest[b].data(), key + o, last + o, tolerance, 3 * n, staged + o, from_key, from_last);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint8_t moved = from_key[3 * i] | from_key[3 * i + 1] | from_key[3 * i + 2];
      flags[b + i] = moved;
      changed += moved;
      moved_since_last += from_last[3 * i] | from_last[3 * i + 1] | from_last[3 * i + 2];
    }
  }
  if (!plausible) throw_bad_delta(pos, rest, a, count);
  if (!compare) changed = count;
  const bool dense = force_ || static_cast<double>(changed) > options_.dense_fraction * static_cast<double>(count);
  if (dense) std::fill(slot.changed.begin(), slot.changed.end(), std::uint8_t{1});
  out.kind = dense ? EncodedChunk::Kind::kDense : changed ? EncodedChunk::Kind::kSparse : EncodedChunk::Kind::kAbsent;
  out.present = static_cast<std::uint32_t>(dense ? count : changed);
  out.moved_since_last = static_cast<std::uint32_t>(force_ ? count : moved_since_last);
  out.runs.clear();
  out.bytes.clear();
  out.max_error = 0.0;

  // Runs of (skip, take) for a sparse chunk.
  if (out.kind == EncodedChunk::Kind::kSparse) {
    std::size_t i = 0;
    while (i < count) {
      std::size_t skip = 0, take = 0;
      while (i < count && !slot.changed[i]) ++skip, ++i;
      while (i < count && slot.changed[i]) ++take, ++i;
      if (take == 0) break;  // trailing unchanged vertices need no run
      out.runs.push_back(static_cast<std::uint32_t>(skip));
      out.runs.push_back(static_cast<std::uint32_t>(take));
    }
  }

  // Only the present deltas, in order (in place: j ≤ i).
  if (!dense) {
    // Branch-free: every vertex is copied down, j advances past present ones.
    float* v = slot.values.data();
    for (std::size_t i = 0, j = 0; i < count; ++i) {
      const float x = v[3 * i], y = v[3 * i + 1], z = v[3 * i + 2];
      v[3 * j] = x, v[3 * j + 1] = y, v[3 * j + 2] = z;
      j += slot.changed[i];
    }
    slot.values.resize(3 * static_cast<std::size_t>(out.present));
  }
  const bool all_zero = std::all_of(slot.values.begin(), slot.values.end(), [](float v) { return v == 0.0f; });

  // Quantization: fixed bits, or the fewest whose exact error meets the target.
  DeltaQuantization q = quantization_over(slot.values, options_.bits ? options_.bits : 8);
  if (options_.bits == 0) q.bits = bits_for_error(q.range, options_.max_error);
  // Pass 2: the decoded values and the exact error, present vertices from the
  // quantization (or exactly 0), absent ones from the keyframe; straight into
  // decoded_, a sparse chunk run by run.
  float* dec = decoded_.data() + 3 * a;
  while (true) {
    if (dense) {
      if (all_zero) {
        std::fill_n(dec, 3 * count, 0.0f);
      } else {
        q.decode(slot.values, std::span<float>(dec, 3 * count));
      }
    } else {
      std::copy_n(keyframe_.data() + 3 * a, 3 * count, dec);
      for (std::size_t r = 0, i = 0, j = 0; r < out.runs.size(); r += 2) {
        i += out.runs[r];
        const std::size_t take = out.runs[r + 1];
        if (all_zero) {
          std::fill_n(dec + 3 * i, 3 * take, 0.0f);
        } else {
          q.decode(std::span<const float>(slot.values).subspan(3 * j, 3 * take), std::span<float>(dec + 3 * i, 3 * take));
        }
        i += take, j += take;
      }
    }
    const double error = max_delta_error(dec, pos->data(), rest->data(), 3 * count);
    out.max_error = error;
    if (options_.bits != 0 || all_zero || out.present == 0 || error <= options_.max_error || q.bits >= 24) break;
    ++q.bits;  // float rounding pushed past the target: one more bit
  }
  out.quantization = all_zero ? DeltaQuantization{q.bits, 0.0f, 0.0f} : q;
  if (all_zero) slot.values.clear();  // nothing for Draco: an empty buffer means zeros
}

void FrameEncoder::encode_chunks(std::size_t first, std::size_t count) {
  if (first > chunks_.size() || count > chunks_.size() - first)
    throw std::out_of_range("chunks " + std::to_string(first) + "+" + std::to_string(count) + " of " +
                            std::to_string(chunks_.size()));
  std::array<DracoChunk, kDracoInterleave> group;
  for (std::size_t c = first; c < first + count; c += group.size()) {
    const std::size_t n = std::min(group.size(), first + count - c);
    for (std::size_t k = 0; k < n; ++k) {
      Slot& slot = chunks_[c + k];
      group[k] = {slot.values, slot.out.quantization, &slot.out.bytes};
    }
    encode_draco_many(std::span(group.data(), n), options_.speed);
  }
  if (options_.staging)
    for (std::size_t c = first; c < first + count; ++c) options_.staging->give(std::exchange(chunks_[c].values, {}));
}

EncodedFrameSummary FrameEncoder::finish() {
  EncodedFrameSummary s;
  s.keyframe = true;
  for (const Slot& slot : chunks_) {
    s.keyframe &= slot.out.kind == EncodedChunk::Kind::kDense;
    s.max_error = std::max(s.max_error, slot.out.max_error);
    s.present_vertices += slot.out.present;
    s.bytes += slot.out.bytes.size() + 4 * slot.out.runs.size();
  }
  // decoded_ holds what clients now show, for every vertex; after a
  // keyframe, that is keyframe_.
  if (s.keyframe) {
    keyframe_.swap(decoded_);
    have_keyframe_ = true;
    keyframe_error_ = s.max_error;
    waste_ = 0;
  } else {
    // Vertices sent only because the keyframe is stale (they moved since it,
    // not since the last frame): once they add up to a whole frame, a fresh
    // keyframe costs less than carrying them on (the rent-or-buy rule).
    std::size_t moved = 0;
    for (const Slot& slot : chunks_) moved += slot.out.moved_since_last;
    waste_ += s.present_vertices > moved ? s.present_vertices - moved : 0;
  }
  previous_is_keyframe_ = s.keyframe;
  force_ = false;
  return s;
}

EncodedFrameSummary FrameEncoder::encode(std::span<const Vec3> positions, bool force_keyframe) {
  begin(force_keyframe);
  for (std::size_t c = 0; c < chunks_.size(); ++c) {
    quantize_chunk(c, positions);
    encode_chunk(c);
  }
  return finish();
}


}  // namespace filigree
