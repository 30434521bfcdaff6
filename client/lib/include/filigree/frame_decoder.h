#pragma once
// Turns a v1::Frame (Draco-compressed posed − rest deltas) into positions.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "filigree/v1/filigree.pb.h"

namespace filigree {

struct DecodedFrame {
  std::uint64_t version = 0;
  std::uint64_t pose_id = 0;     // for a driver: its newest pose included (0 if none)
  std::vector<float> positions;  // 3·n, rest + decoded deltas, original order
  float max_error = 0.0f;        // largest |decoded − exact| coordinate error
  v1::FrameStats stats;
  std::vector<v1::Change> changes;  // who changed what since the previous frame
  std::size_t encoded_bytes = 0;    // size of the compressed deltas on the wire
};

// Holds the rest positions of one session; decode() is const and may be
// called from several threads at once.
class FrameDecoder {
 public:
  // `rest_positions`: 3·n floats, SessionMesh::rest_positions.
  explicit FrameDecoder(std::vector<float> rest_positions);

  // Decodes `frame`. Throws ClientError (DATA_LOSS) if its vertex count is
  // not the rest mesh's or its deltas cannot be decoded; never reads out of
  // bounds on a corrupt frame.
  DecodedFrame decode(const v1::Frame& frame) const;

  std::size_t vertex_count() const { return rest_.size() / 3; }
  const std::vector<float>& rest_positions() const { return rest_; }

 private:
  std::vector<float> rest_;
};

}  // namespace filigree
