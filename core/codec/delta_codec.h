#pragma once
// Frame deltas on the wire (DESIGN §3): posed − rest for every vertex, in
// vertex order, as a Draco point cloud with sequential (order-preserving)
// encoding and explicit quantization.

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "codec/delta_quantization.h"
#include "codec/draco_writer.h"
#include "mesh/tri_mesh.h"

namespace filigree {

struct EncodedDeltas {
  std::string bytes;        // the Draco buffer; empty when every delta is 0
  std::uint32_t count = 0;  // number of vectors
  std::uint32_t bits = 14;  // quantization bits
  float min = 0.0f;         // quantization range: [min, min + range] on every axis
  float range = 0.0f;
  // Largest |decoded − input| over all coordinates, computed from the
  // quantization (DeltaQuantization), rounded up to a float.
  float max_error = 0.0f;
};

// A buffer that cannot be decoded; what() says why.
struct DeltaCodecError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Throws DeltaCodecError naming `vertex` unless |d| ≤ kMaxDeltaMagnitude
// (so also for NaN and ±∞): a delta no frame can carry.
[[noreturn]] void throw_implausible_delta(double d, std::size_t vertex);
inline void check_delta(double d, std::size_t vertex) {
  if (!(d <= kMaxDeltaMagnitude && d >= -kMaxDeltaMagnitude)) throw_implausible_delta(d, vertex);
}

// Encodes `deltas` with `bits` (8…24) of quantization over their own range.
// Throws DeltaCodecError for bad bits or non-finite deltas (and for
// |delta| > 1e30, which float32 quantization cannot carry).
// max_error is exact (DeltaQuantization), at most bound(). Thread-safe.
EncodedDeltas encode_deltas(const std::vector<Vec3>& deltas, std::uint32_t bits);

// Decodes a buffer of `count` points (as decode_deltas) into `out`, 3·count
// floats. An empty buffer is all zeros.
void decode_deltas_into(std::string_view bytes, std::uint32_t count, std::span<float> out);

// Decodes what encode_deltas produced (also accepting an empty buffer as all
// zeros). Throws DeltaCodecError on a corrupt buffer or a count mismatch;
// never reads out of bounds. A Draco buffer carries no checksum: damage inside
// the entropy-coded values often still decodes, to wrong finite values, so
// integrity is the transport's job. Non-finite decoded values are rejected.
std::vector<Vec3> decode_deltas(const EncodedDeltas& encoded);

}  // namespace filigree
