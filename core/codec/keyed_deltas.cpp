#include "codec/keyed_deltas.h"

#include <algorithm>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include "codec/delta_codec.h"

namespace filigree {
namespace {

// Checks a frame's chunks; `present` gets each chunk's present count.
void check_chunks(std::span<const DeltaChunkView> chunks, std::size_t n, std::vector<std::uint32_t>& present) {
  present.resize(chunks.size());
  std::uint64_t next = 0;
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    const DeltaChunkView& k = chunks[c];
    const std::string which = "chunk " + std::to_string(c) + " (vertices " + std::to_string(k.first) + "+" +
                              std::to_string(k.count) + ")";
    if (k.first < next) throw DeltaCodecError(which + " overlaps or precedes the previous chunk");
    if (std::uint64_t{k.first} + k.count > n)
      throw DeltaCodecError(which + " reaches past the mesh's " + std::to_string(n) + " vertices");
    next = std::uint64_t{k.first} + k.count;
    if (k.runs.empty()) {
      present[c] = k.count;
      continue;
    }
    if (k.runs.size() % 2 != 0) throw DeltaCodecError(which + " has an odd number of runs");
    std::uint64_t covered = 0, taken = 0;
    for (std::size_t r = 0; r < k.runs.size(); r += 2) covered += std::uint64_t{k.runs[r]} + k.runs[r + 1], taken += k.runs[r + 1];
    if (covered > k.count) throw DeltaCodecError(which + " has runs covering " + std::to_string(covered) + " vertices");
    present[c] = static_cast<std::uint32_t>(taken);
  }
}

// Runs `work(c)` for every chunk on up to `threads` threads; rethrows the first error.
template <class Work>
void for_each_chunk(std::size_t chunks, unsigned threads, const Work& work) {
  threads = std::max(1u, std::min<unsigned>(threads, static_cast<unsigned>(chunks)));
  if (threads <= 1) {
    for (std::size_t c = 0; c < chunks; ++c) work(c);
    return;
  }
  std::exception_ptr error;
  std::mutex mutex;
  {
    std::vector<std::jthread> pool;
    for (unsigned t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        try {
          for (std::size_t c = t; c < chunks; c += threads) work(c);
        } catch (...) {
          std::lock_guard lock(mutex);
          if (!error) error = std::current_exception();
        }
      });
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace

KeyedDeltas::KeyedDeltas(std::size_t vertex_count) : keyframe_(3 * vertex_count, 0.0f) {}

std::span<const float> KeyedDeltas::deltas() const { return showing_keyframe_ ? keyframe_ : current_; }

void KeyedDeltas::apply(std::uint64_t version, std::uint64_t keyframe_version, std::span<const DeltaChunkView> chunks,
                        unsigned threads) {
  const std::size_t n = vertex_count();
  std::vector<std::uint32_t>& present = present_;
  check_chunks(chunks, n, present);
  const std::string where = "frame " + std::to_string(version) + ": ";

  if (version == keyframe_version) {
    // Ranges are in order and disjoint (checked): whole chunks summing to n cover every vertex.
    std::uint64_t listed = 0;
    bool whole = true;
    for (const DeltaChunkView& k : chunks) listed += k.count, whole &= k.runs.empty();
    if (!whole || listed != n) throw DeltaCodecError(where + "a keyframe must list every vertex, in whole chunks");
    // Decoded into a scratch copy first: a corrupt chunk must leave the held keyframe intact.
    scratch_.resize(3 * n);
    try {
      for_each_chunk(chunks.size(), threads, [&](std::size_t c) {
        const DeltaChunkView& k = chunks[c];
        decode_deltas_into(k.bytes, k.count, std::span<float>(scratch_).subspan(3 * std::size_t{k.first}, 3 * std::size_t{k.count}));
      });
    } catch (const DeltaCodecError& e) {
      throw DeltaCodecError(where + e.what());
    }
    keyframe_.swap(scratch_);
    keyframe_version_ = keyframe_version;
    showing_keyframe_ = true;
    current_from_keyframe_ = false;
    dirty_.clear();
    return;
  }

  if (keyframe_version != keyframe_version_)
    throw DeltaCodecError(where + "is relative to keyframe " + std::to_string(keyframe_version) +
                          ", and the keyframe held is " + std::to_string(keyframe_version_));
  // Present values of every chunk, decoded before anything changes.
  std::vector<std::size_t>& offset = offset_;
  offset.assign(chunks.size() + 1, 0);
  for (std::size_t c = 0; c < chunks.size(); ++c) offset[c + 1] = offset[c] + 3 * std::size_t{present[c]};
  scratch_.resize(offset.back());
  try {
    for_each_chunk(chunks.size(), threads, [&](std::size_t c) {
      decode_deltas_into(chunks[c].bytes, present[c], std::span<float>(scratch_).subspan(offset[c], offset[c + 1] - offset[c]));
    });
  } catch (const DeltaCodecError& e) {
    throw DeltaCodecError(where + e.what());
  }
  // current_ = keyframe, restoring only what the previous sparse frame changed.
  if (!current_from_keyframe_) {
    current_ = keyframe_;
    current_from_keyframe_ = true;
  } else {
    for (const auto& [first, count] : dirty_)
      std::copy_n(keyframe_.data() + 3 * std::size_t{first}, 3 * std::size_t{count}, current_.data() + 3 * std::size_t{first});
  }
  dirty_.clear();
  for (std::size_t c = 0; c < chunks.size(); ++c) {
    const DeltaChunkView& k = chunks[c];
    // data() + offset, not &v[i]: v may be empty (a frame of no vertices; found by fuzz_frame).
    const float* values = scratch_.data() + offset[c];
    float* out = current_.data() + 3 * std::size_t{k.first};
    if (k.runs.empty()) {
      std::copy_n(values, 3 * std::size_t{k.count}, out);
    } else {
      std::size_t at = 0;
      for (std::size_t r = 0; r < k.runs.size(); r += 2) {
        at += k.runs[r];
        std::copy_n(values, 3 * std::size_t{k.runs[r + 1]}, out + 3 * at);
        values += 3 * std::size_t{k.runs[r + 1]};
        at += k.runs[r + 1];
      }
    }
    dirty_.emplace_back(k.first, k.count);
  }
  showing_keyframe_ = false;
}

}  // namespace filigree
