#pragma once
// Draco's own encoder for the stream encode_draco writes (draco_writer.h):
// the reference the tests compare encode_draco with byte for byte, and the
// benches' baseline. Not for frames: it is several times slower.

#include <span>
#include <string>

#include "codec/delta_quantization.h"

namespace filigree {

// Draco-encodes `values` (x y z per point, every value inside q's range; the
// caller checked them finite) as a sequential point cloud quantized by `q`,
// with Draco 1.5's ExpertEncoder at `speed`. Throws DeltaCodecError if Draco
// fails. Empty values give an empty string.
std::string encode_with_draco_library(std::span<const float> values, const DeltaQuantization& q, int speed);

}  // namespace filigree
