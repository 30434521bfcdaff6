#include "codec/frame_encoder.h"

#include <algorithm>
#include <array>
#include <bit>
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

// The first i' ≥ i below `end` whose bit is `set` (end if none).
std::size_t next_bit(const std::vector<std::uint64_t>& bits, std::size_t i, std::size_t end, bool set) {
  while (i < end) {
    std::uint64_t word = bits[i / 64] ^ (set ? 0 : ~std::uint64_t{0});
    word &= ~std::uint64_t{0} << (i % 64);
    if (word) return std::min(end, (i / 64) * 64 + static_cast<std::size_t>(std::countr_zero(word)));
    i = (i / 64 + 1) * 64;
  }
  return end;
}

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

  // The one pass over the positions (delta_staging.h): the deltas staged in
  // float32 (as Draco will store them), which vertices moved away from the
  // keyframe and how many from the previous frame (to know when a fresh
  // keyframe pays off), and what the error statement below needs.
  if (options_.staging && slot.values.capacity() == 0) {
    slot.values = options_.staging->take(3 * count);
  } else {
    slot.values.resize(3 * count);
  }
  slot.moved.resize((count + 63) / 64);
  const Vec3* pos = positions.data() + a;
  const Vec3* rest = rest_.data() + a;
  const bool compare = !force_;
  const float* key = compare ? keyframe_.data() + 3 * a : nullptr;
  // What clients showed after the previous frame: the keyframe's deltas
  // where that frame was the keyframe or left this chunk out (out.kind is
  // still the previous frame's here; a left-out chunk writes no decoded_).
  const bool showed_keyframe = previous_is_keyframe_ || out.kind == EncodedChunk::Kind::kAbsent;
  const float* last = compare ? (showed_keyframe ? keyframe_ : decoded_).data() + 3 * a : nullptr;
  const StagingSummary st = stage_vertices(pos->data(), rest->data(), key, last, tolerance, count, slot.values.data(), slot.moved.data());
  if (!st.plausible) throw_bad_delta(pos, rest, a, count);
  const std::size_t changed = st.moved;
  const bool dense = force_ || static_cast<double>(changed) > options_.dense_fraction * static_cast<double>(count);
  out.kind = dense ? EncodedChunk::Kind::kDense : changed ? EncodedChunk::Kind::kSparse : EncodedChunk::Kind::kAbsent;
  out.present = static_cast<std::uint32_t>(dense ? count : changed);
  out.moved_since_last = static_cast<std::uint32_t>(st.moved_since_last);
  out.runs.clear();
  out.bytes.clear();
  out.max_error = 0.0;

  if (out.kind == EncodedChunk::Kind::kSparse) {
    // Runs of (skip, take); trailing unmoved vertices need none.
    for (std::size_t done = 0, i = next_bit(slot.moved, 0, count, true); i < count; i = next_bit(slot.moved, done, count, true)) {
      const std::size_t end = next_bit(slot.moved, i, count, false);
      out.runs.push_back(static_cast<std::uint32_t>(i - done));
      out.runs.push_back(static_cast<std::uint32_t>(end - i));
      done = end;
    }
    // Only the present deltas, in order.
    compact_moved(slot.values.data(), slot.moved.data(), count);
  }
  slot.values.resize(3 * static_cast<std::size_t>(out.present));
  const float lo = dense ? st.lo : st.moved_lo, hi = dense ? st.hi : st.moved_hi;
  const bool all_zero = out.present == 0 || (lo == 0.0f && hi == 0.0f);

  // Quantization: fixed bits, or the fewest whose error meets the target.
  DeltaQuantization q{.bits = options_.bits ? options_.bits : 8u};
  if (out.present) q = quantization_over_range(lo, hi, q.bits);
  if (options_.bits == 0) q.bits = bits_for_error(q.range, options_.max_error);
  // Pass 2, over the staged floats only: what clients will decode, straight
  // into decoded_ (a sparse chunk's absent vertices keep the keyframe's, its
  // present ones decoded run by run; an absent chunk writes nothing: clients
  // show the keyframe's deltas there, and so a local motion, which leaves
  // most chunks out, neither copies the keyframe nor reads a copy back), and
  // the stated error. An absent vertex's error is exact (from the pass
  // above); a present one's is |decoded − s| + |s − d| at most, both
  // measured (d the delta in double, s its float): an upper bound above the
  // exact error by at most twice the staging's rounding (2^-24 of the
  // largest delta).
  float* dec = decoded_.data() + 3 * a;
  const auto present_error = [&](double decode_error) { return (decode_error + st.rounding) * (1.0 + 0x1p-50); };
  while (true) {
    double decode_error = 0.0;
    if (dense) {
      if (all_zero) {
        std::fill_n(dec, 3 * count, 0.0f);
      } else {
        decode_error = q.decode_measured(slot.values, std::span<float>(dec, 3 * count));
      }
    } else if (out.kind == EncodedChunk::Kind::kSparse) {
      std::copy_n(keyframe_.data() + 3 * a, 3 * count, dec);
      for (std::size_t r = 0, i = 0, j = 0; r < out.runs.size(); r += 2) {
        i += out.runs[r];
        const std::size_t take = out.runs[r + 1];
        if (all_zero) {
          std::fill_n(dec + 3 * i, 3 * take, 0.0f);
        } else {
          decode_error = std::max(decode_error, q.decode_measured(std::span<const float>(slot.values).subspan(3 * j, 3 * take),
                                                                  std::span<float>(dec + 3 * i, 3 * take)));
        }
        i += take, j += take;
      }
    }
    const double error = std::max(out.present ? present_error(decode_error) : 0.0, dense ? 0.0 : st.unmoved_error);
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
