#pragma once
// Turns v1::Frames (Draco-compressed posed − rest deltas) into positions.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

class KeyedDeltas;

struct DecodedFrame {
  std::uint64_t version = 0;
  std::uint64_t pose_id = 0;     // for a driver: its newest pose included (0 if none)
  std::vector<float> positions;  // 3·n, rest + decoded deltas, original order
  float max_error = 0.0f;        // largest |decoded − exact| coordinate error
  v1::FrameStats stats;
  std::vector<v1::Change> changes;  // who changed what since the previous frame
  std::size_t encoded_bytes = 0;    // size of the compressed deltas on the wire (chunks and runs)
  bool keyframe = true;             // chunked: a keyframe; false: a sparse frame
  std::size_t present_vertices = 0; // vertices the frame carried
  // A clip's stream (Client::play_clip): the clip time, in seconds, of the
  // newest sample of that stream the frame includes (pose_id is its number);
  // 0 when it includes none, and on other streams.
  double clip_seconds = 0.0;
};

// Decodes the frames of one stream, in the order they arrive: both formats
// (FRAME_FORMAT_SINGLE, and FRAME_FORMAT_CHUNKED, whose sparse frames need
// the keyframe received before them; the server always sends it first). One
// decoder per stream; not thread-safe, but decodes a frame's chunks on
// `threads` threads.
class FrameDecoder {
 public:
  // `rest_positions`: 3·n floats, SessionMesh::rest_positions. `threads`: 0
  // picks the hardware's.
  explicit FrameDecoder(std::vector<float> rest_positions, unsigned threads = 0);
  ~FrameDecoder();
  FrameDecoder(FrameDecoder&&) noexcept;
  FrameDecoder& operator=(FrameDecoder&&) noexcept;

  // Decodes `frame`. Throws ClientError (DATA_LOSS) if its vertex count is
  // not the rest mesh's, its deltas cannot be decoded, or it is sparse against
  // a keyframe this decoder has not decoded; the held keyframe is then kept.
  // Never reads out of bounds on a corrupt frame.
  DecodedFrame decode(const v1::Frame& frame);

  std::size_t vertex_count() const { return rest_.size() / 3; }
  const std::vector<float>& rest_positions() const { return rest_; }

 private:
  std::vector<float> rest_;
  unsigned threads_;
  std::unique_ptr<KeyedDeltas> keyed_;
};

}  // namespace filigree
