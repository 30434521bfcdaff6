#pragma once
// Frames' Draco buffers, written by us (DESIGN §3). Every frame chunk is one
// Draco bitstream of a single kind: a point cloud of float32×3 values,
// sequential (order-preserving) encoding, explicit quantization, difference
// prediction with Draco's wrap transform, and Draco's rANS symbol coding.
// encode_draco writes that stream directly, byte for byte what Draco 1.5's
// ExpertEncoder writes for the same values, quantization and speed (the tests
// compare them, and decode with Draco's decoder). Why not Draco's encoder:
// it builds a point cloud, converts the values through three attribute
// objects, estimates both entropy coders with fresh tables and divides once
// per symbol, 48–58 ns per vertex; this is a few flat passes over the chunk.
// Every client keeps decoding with Draco (libdraco, draco3d).

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "codec/delta_quantization.h"

namespace filigree {

// Draco's encoding speed (0 smallest … 10 fastest); for this stream it only
// sets the entropy coder's precision. Measured on 435k real deltas in chunks
// of 16384 (Draco 1.5.5): 5 gives 1.26 B/vertex in the same time as 10,
// which gives 1.31; below 5 decoding slows down for < 1% smaller.
constexpr int kDefaultEncodingSpeed = 5;
// The speeds the writer takes. (Draco itself reads −1 as its default and
// others outside 0…10 as level 7; we refuse them instead.)
constexpr bool is_encoding_speed(int speed) { return speed >= 0 && speed <= 10; }

// Writes `values` (x y z per point) quantized by `q` into `out` (replacing
// its contents, keeping its capacity). Preconditions: values.size() is a
// multiple of 3 and below 2^31; every value is finite and inside [q.min,
// q.min + q.range]; q.range > 0. Empty values give an empty string. Throws
// DeltaCodecError for a speed outside 0…10 and where Draco's encoder would
// fail. Thread-safe. Its scratch is per thread and reused, so the only
// allocation is `out`'s, when the caller did not keep its capacity (the
// server moves each chunk's bytes into the frame it sends).
void encode_draco_into(std::span<const float> values, const DeltaQuantization& q, int speed, std::string& out);

// One chunk for encode_draco_many: what encode_draco_into takes.
struct DracoChunk {
  std::span<const float> values;
  DeltaQuantization quantization;
  std::string* out = nullptr;
};

// The most chunks whose entropy coders encode_draco_many runs in one loop.
inline constexpr std::size_t kDracoInterleave = 4;

// Writes every chunk's buffer, byte for byte what encode_draco_into writes
// for it, with the same preconditions, taking them kDracoInterleave at a
// time. rANS is a chain of dependent steps per value and Draco's stream has
// one coder per buffer, so a lone chunk leaves most of a core idle; the
// coders of a group run in one loop and overlap. On a throw every out's
// contents are unspecified. Thread-safe, like encode_draco_into.
void encode_draco_many(std::span<const DracoChunk> chunks, int speed);

// The same, returning a new string.
std::string encode_draco(std::span<const float> values, const DeltaQuantization& q,
                         int speed = kDefaultEncodingSpeed);

}  // namespace filigree
