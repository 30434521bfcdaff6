#pragma once
// Frame deltas on the wire (DESIGN §3): posed − rest for every vertex, in
// vertex order, as a Draco point cloud with sequential (order-preserving)
// encoding and explicit quantization.

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct EncodedDeltas {
  std::string bytes;        // the Draco buffer; empty when every delta is 0
  std::uint32_t count = 0;  // number of vectors
  std::uint32_t bits = 14;  // quantization bits
  float min = 0.0f;         // quantization range: [min, min + range] on every axis
  float range = 0.0f;
  // Largest |decoded − input| over all coordinates, measured after encoding.
  float max_error = 0.0f;
};

// A buffer that cannot be decoded; what() says why.
struct DeltaCodecError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Encodes `deltas` with `bits` (8…24) of quantization over their own range.
// Throws DeltaCodecError for bad bits or non-finite deltas (and for
// |delta| > 1e30, which float32 quantization cannot carry).
// max_error is measured by decoding the result once; it is at most half a
// step, range / (2^bits − 1) / 2, plus float32 rounding (Draco quantizes in
// float). Thread-safe: every call uses its own Draco encoder and decoder.
EncodedDeltas encode_deltas(const std::vector<Vec3>& deltas, std::uint32_t bits);

// Decodes what encode_deltas produced (also accepting an empty buffer as all
// zeros). Throws DeltaCodecError on a corrupt buffer or a count mismatch;
// never reads out of bounds. A Draco buffer carries no checksum: damage inside
// the entropy-coded values often still decodes, to wrong finite values, so
// integrity is the transport's job. Non-finite decoded values are rejected.
std::vector<Vec3> decode_deltas(const EncodedDeltas& encoded);

}  // namespace filigree
