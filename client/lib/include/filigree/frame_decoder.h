#pragma once
// Turns v1::Frames (Draco-compressed posed − rest deltas) into positions, at
// full detail or at a level of detail (DecodedLevel).

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "filigree/decoded_level.h"
#include "filigree/v1/filigree.pb.h"

namespace filigree {

class KeyedDeltas;

struct DecodedFrame {
  std::uint64_t version = 0;
  std::uint64_t pose_id = 0;     // for a driver: its newest pose included (0 if none)
  // 3 per vertex, rest + decoded deltas: 3·n in session order at full
  // detail; at a level, 3·level->vertex_count, the level's vertices in order.
  std::vector<float> positions;
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
  // The level of detail the frame is at (the decoder's when it decoded it);
  // null for a stream at full detail that never received a level.
  std::shared_ptr<const DecodedLevel> level;

  std::size_t vertex_count() const { return positions.size() / 3; }
};

// Decodes the frames of one stream, in the order they arrive: both formats
// (FRAME_FORMAT_SINGLE, and FRAME_FORMAT_CHUNKED, whose sparse frames need
// the keyframe received before them; the server always sends it first). One
// decoder per stream; not thread-safe, but decodes a frame's chunks on
// `threads` threads.
//
// A stream opened with a vertex budget (WatchOptions::max_vertices,
// DriveOptions::max_vertices) starts with a message that carries only a
// level (v1::Frame::has_level()), and so does every change of level: give
// those to set_level(), the frames to decode().
//
//   while (auto message = watcher->read())
//     if (message->has_level()) decoder.set_level(message->level());
//     else draw(decoder.decode(*message));  // at decoder.level()
class FrameDecoder {
 public:
  // `rest_positions`: 3·n floats, SessionMesh::rest_positions. `threads`: 0
  // picks the hardware's.
  explicit FrameDecoder(std::vector<float> rest_positions, unsigned threads = 0);
  ~FrameDecoder();
  FrameDecoder(FrameDecoder&&) noexcept;
  FrameDecoder& operator=(FrameDecoder&&) noexcept;

  // Decodes `frame`. Throws ClientError (DATA_LOSS) if its vertex count is
  // not the current level's (the rest mesh's at full detail), its
  // level_vertices names another level, its deltas cannot be decoded, or it
  // is sparse against a keyframe this decoder has not decoded; the held
  // keyframe is then kept. Never reads out of bounds on a corrupt frame.
  // INVALID_ARGUMENT for a message that carries a level (set_level's).
  DecodedFrame decode(const v1::Frame& frame);

  // Starts the level `level` (v1::Frame::level()): later frames are its
  // frames, and the keyframe held is dropped (the stream sends the level's
  // next). Throws ClientError (DATA_LOSS) for a level that does not fit the
  // rest mesh (decode_level); the decoder's level is then unchanged.
  const DecodedLevel& set_level(const v1::DetailLevel& level);
  // The current level; null until set_level (a stream at full detail).
  const std::shared_ptr<const DecodedLevel>& level() const { return level_; }

  // The full mesh's (the rest mesh's) vertex count and positions.
  std::size_t vertex_count() const { return rest_.size() / 3; }
  const std::vector<float>& rest_positions() const { return rest_; }

 private:
  std::vector<float> rest_;
  unsigned threads_;
  std::unique_ptr<KeyedDeltas> keyed_;  // sized to the current level
  std::shared_ptr<const DecodedLevel> level_;
};

}  // namespace filigree
