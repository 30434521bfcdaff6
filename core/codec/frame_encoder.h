#pragma once
// Frames as chunks of vertex ranges, sparse against a keyframe (DESIGN §3,
// proto Frame.chunks). One FrameEncoder per session keeps the keyframe's
// decoded deltas; each frame is quantized and Draco-encoded chunk by chunk,
// chunks in parallel (distinct chunks on distinct threads).
//
// A vertex is *present* in a frame when its delta moved more than the
// tolerance away from what clients hold for it (the keyframe's decoded delta).
// A chunk with more than `dense_fraction` of its vertices present is sent
// whole; one with none is left out; others list their present vertices as
// runs. A frame in which every chunk is whole is a keyframe: clients replace
// their keyframe with it, and so does the encoder. When the vertices sent only
// because the keyframe is old (they moved since it, not since the previous
// frame) add up to a whole frame, the next frame is a keyframe.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "codec/delta_quantization.h"
#include "codec/draco_writer.h"
#include "mesh/tri_mesh.h"
#include "util/buffer_pool.h"

namespace filigree {

struct FrameEncoderOptions {
  std::uint32_t chunk_vertices = 16384;  // fixed ranges: [k·chunk, (k+1)·chunk)
  // Fixed quantization bits (8…24), or 0: per chunk, the fewest bits that
  // keep every error ≤ max_error.
  std::uint32_t bits = 0;
  double max_error = 0.0;  // absolute; with bits = 0 it must be > 0
  double dense_fraction = 0.5;
  int speed = kDefaultEncodingSpeed;  // Draco encoding speed (draco_writer.h)
  // Where a chunk's staged deltas live from quantize_chunk to encode_chunk;
  // shared by the encoders of many sessions, so an idle one holds none.
  // Null: each chunk keeps its own buffer.
  std::shared_ptr<BufferPool<float>> staging = nullptr;
};

struct EncodedChunk {
  enum class Kind { kAbsent, kSparse, kDense };
  Kind kind = Kind::kAbsent;
  std::uint32_t first = 0, count = 0;   // the range
  std::uint32_t present = 0;            // vertices carried
  std::uint32_t moved_since_last = 0;   // vertices that moved since the previous frame
  std::vector<std::uint32_t> runs;      // kSparse: skip, take, skip, take …
  std::string bytes;                    // Draco buffer; empty: every present delta is 0
  DeltaQuantization quantization;
  // Over the whole range (absent vertices too): an upper bound on what a
  // client's decode is off by, above the exact error by at most twice the
  // float32 rounding of the largest delta (2^-24 of it).
  double max_error = 0.0;
};

struct EncodedFrameSummary {
  bool keyframe = false;
  double max_error = 0.0;         // over every vertex, as EncodedChunk::max_error
  std::size_t present_vertices = 0;
  std::size_t bytes = 0;          // Draco bytes + 4 per run
};

class FrameEncoder {
 public:
  // `rest`: the rest positions, original order (kept by reference: the
  // caller keeps them alive). Throws std::invalid_argument on bad options.
  FrameEncoder(std::span<const Vec3> rest, FrameEncoderOptions options);

  std::size_t chunk_count() const { return chunks_.size(); }
  // How many chunks a mesh of `vertices` is split into with `chunk_vertices` (> 0).
  static std::size_t chunk_count(std::size_t vertices, std::size_t chunk_vertices) {
    return (vertices + chunk_vertices - 1) / chunk_vertices;
  }
  std::size_t vertex_count() const { return rest_.size(); }

  // Starts a frame; every chunk must then be quantized, encoded, and the
  // frame finished. force_keyframe: every chunk whole (the first frame is).
  void begin(bool force_keyframe);
  // Reads positions[range of chunk c] (posed, original order, every vertex),
  // once: decides what is present, quantizes it and bounds the error.
  // After it returns the positions of that range are not read again.
  // Throws DeltaCodecError for a non-finite or implausible delta.
  void quantize_chunk(std::size_t c, std::span<const Vec3> positions);
  // Draco-encodes chunk c (after quantize_chunk(c)).
  void encode_chunk(std::size_t c) { encode_chunks(c, 1); }
  // Draco-encodes chunks [first, first + count) (each after its
  // quantize_chunk), their entropy coders interleaved (encode_draco_many):
  // the same bytes as one at a time, in less time on one thread.
  void encode_chunks(std::size_t first, std::size_t count);
  // What encode_chunk(c) will encode: chunk c's present deltas, x y z each
  // (valid between quantize_chunk(c) and encode_chunk(c)).
  std::span<const float> staged(std::size_t c) const { return chunks_.at(c).values; }
  // After every chunk: the frame's summary; a keyframe becomes the reference.
  EncodedFrameSummary finish();

  // Chunk c of the frame last finished (or being encoded).
  const EncodedChunk& chunk(std::size_t c) const { return chunks_[c].out; }
  EncodedChunk& chunk(std::size_t c) { return chunks_[c].out; }

  // Convenience, one thread: the whole frame.
  EncodedFrameSummary encode(std::span<const Vec3> positions, bool force_keyframe);

 private:
  struct Slot {
    EncodedChunk out;
    std::vector<float> values;       // present deltas, x y z
    std::vector<std::uint64_t> moved;  // bit i: vertex first + i moved from the keyframe
  };
  std::span<const Vec3> rest_;
  FrameEncoderOptions options_;
  std::vector<Slot> chunks_;
  std::vector<float> keyframe_;  // decoded deltas clients hold, 3·n
  std::vector<float> decoded_;   // this frame's decoded deltas, but for the chunks it leaves out
  bool have_keyframe_ = false;
  bool force_ = false;
  bool previous_is_keyframe_ = true;
  std::size_t waste_ = 0;  // vertices sent since the keyframe only because it is stale
  double keyframe_error_ = 0.0;
};

}  // namespace filigree
