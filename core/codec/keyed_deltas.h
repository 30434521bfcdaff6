#pragma once
// A client's side of chunked frames (proto Frame.chunks): the deltas of the
// latest keyframe and of the latest frame, updated in place. A keyframe
// replaces the keyframe; a sparse frame is the keyframe plus its present
// vertices, so only the ranges the previous sparse frame touched are restored.

#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

namespace filigree {

// One DeltaChunk as received (views into the message).
struct DeltaChunkView {
  std::uint32_t first = 0, count = 0;
  std::span<const std::uint32_t> runs;  // skip, take, … (empty: all present)
  std::string_view bytes;               // Draco buffer of the present vertices
};

class KeyedDeltas {
 public:
  explicit KeyedDeltas(std::size_t vertex_count);

  // Applies frame `version` relative to keyframe `keyframe_version` (equal:
  // a keyframe). Decodes chunks on up to `threads` threads. Throws
  // DeltaCodecError, leaving the held keyframe unchanged, for a corrupt chunk,
  // ranges out of order, overlapping or past the mesh, runs past their range,
  // a keyframe that does not list every vertex, or a sparse frame relative to
  // a keyframe other than the one held.
  void apply(std::uint64_t version, std::uint64_t keyframe_version, std::span<const DeltaChunkView> chunks,
             unsigned threads = 1);

  // The latest frame's deltas, 3 per vertex (zeros before any frame).
  std::span<const float> deltas() const;
  // The keyframe held (0 and all-zero deltas before the first).
  std::uint64_t keyframe_version() const { return keyframe_version_; }
  std::size_t vertex_count() const { return keyframe_.size() / 3; }

 private:
  std::vector<float> keyframe_, current_, scratch_;
  std::vector<std::uint32_t> present_;  // per chunk of the frame applied (reused)
  std::vector<std::size_t> offset_;     // where each chunk's values start in scratch_
  std::uint64_t keyframe_version_ = 0;
  bool showing_keyframe_ = true;    // deltas() is the keyframe itself
  bool current_from_keyframe_ = false;  // current_ equals keyframe_ outside dirty_
  std::vector<std::pair<std::uint32_t, std::uint32_t>> dirty_;  // ranges of current_ ≠ keyframe_
};

}  // namespace filigree
