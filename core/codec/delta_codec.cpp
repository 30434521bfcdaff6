// Frame deltas as a Draco point cloud (DESIGN §3, TOOLCHAIN "Draco").
//
// Encoding: one float32×3 GENERIC attribute, one value per point in vertex
// order, sequential so that point i stays point i (Draco's default for point
// clouds is the kd-tree, which reorders), written by encode_draco
// (draco_writer.h). Sequential point clouds use difference prediction from
// the previous point, so the size depends on how spatially coherent the
// vertex order is.
//
// Quantization is explicit, over the deltas' own range with one range for all
// three axes: origin = min over all components, range = max − min, and Draco's
// step is range / (2^bits − 1). Draco quantizes and dequantizes in float, so
// the error is step/2 plus a few float roundings; DeltaQuantization computes
// the decoded values exactly, and max_error is their largest error (rounded up).
//
// Decoding trusts nothing in the buffer. Before Draco sees it, the header is
// checked against what encode_deltas writes (a sequential point cloud without
// metadata) and the point count in it against `count`, so a corrupt count
// cannot make Draco allocate for billions of points; after decoding, the
// attribute's type, size and mapping are checked before any value is read.
//
// Every call builds its own Draco decoder: nothing is shared between threads.

#include "codec/delta_codec.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <memory>
#include <utility>

#include <draco/attributes/point_attribute.h>
#include <draco/compression/decode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/draco_types.h>
#include <draco/point_cloud/point_cloud.h>

namespace filigree {
namespace {

constexpr std::uint32_t kMinBits = 8;
constexpr std::uint32_t kMaxBits = 24;

// The fixed part of a Draco header (draco/compression/point_cloud/
// point_cloud_decoder.cc, DecodeHeader): "DRACO", major, minor, encoder type,
// encoder method, uint16 flags. A sequential point cloud then starts with its
// int32 point count (point_cloud_sequential_decoder.cc, DecodeGeometryData).
constexpr std::size_t kHeaderSize = 11;
constexpr std::size_t kEncoderTypeOffset = 7;
constexpr std::size_t kEncoderMethodOffset = 8;
constexpr std::size_t kFlagsOffset = 9;
constexpr std::size_t kNumPointsOffset = kHeaderSize;

// Reads what decode would read, without Draco, and rejects anything that
// encode_deltas cannot have written.
void check_header(std::string_view bytes, std::uint32_t count) {
  if (bytes.size() < kNumPointsOffset + 4) {
    throw DeltaCodecError("delta buffer truncated: " + std::to_string(bytes.size()) +
                          " bytes is shorter than a Draco point cloud header");
  }
  if (std::memcmp(bytes.data(), "DRACO", 5) != 0) {
    throw DeltaCodecError("delta buffer is not a Draco buffer (no DRACO magic)");
  }
  const auto byte_at = [&](std::size_t i) { return static_cast<unsigned char>(bytes[i]); };
  if (byte_at(kEncoderTypeOffset) != draco::POINT_CLOUD) {
    throw DeltaCodecError("delta buffer holds a Draco mesh, not a point cloud");
  }
  if (byte_at(kEncoderMethodOffset) != draco::POINT_CLOUD_SEQUENTIAL_ENCODING) {
    throw DeltaCodecError("delta buffer is not sequentially encoded (vertex order not preserved)");
  }
  if (byte_at(kFlagsOffset) != 0 || byte_at(kFlagsOffset + 1) != 0) {
    throw DeltaCodecError("delta buffer has unexpected Draco header flags (metadata?)");
  }
  // Little-endian int32, assembled byte by byte (no alignment or endianness
  // assumption).
  std::uint32_t stored = 0;
  for (std::size_t i = 0; i < 4; ++i) {
    stored |= static_cast<std::uint32_t>(byte_at(kNumPointsOffset + i)) << (8 * i);
  }
  if (stored != count) {
    throw DeltaCodecError("delta buffer holds " + std::to_string(stored) + " points, the frame says " +
                          std::to_string(count));
  }
}

// Decodes a non-empty buffer of `count` points into out (3·count); every check is fatal.
void decode_draco(std::string_view bytes, std::uint32_t count, std::span<float> out) {
  check_header(bytes, count);

  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodePointCloudFromBuffer(&buffer);
  if (!decoded.ok()) {
    throw DeltaCodecError("Draco could not decode the delta buffer: " +
                          decoded.status().error_msg_string());
  }
  const std::unique_ptr<draco::PointCloud> cloud = std::move(decoded).value();
  if (!cloud) throw DeltaCodecError("Draco returned no point cloud for the delta buffer");
  if (cloud->num_points() != count) {
    throw DeltaCodecError("delta buffer decoded to " + std::to_string(cloud->num_points()) +
                          " points, the frame says " + std::to_string(count));
  }
  if (cloud->num_attributes() != 1) {
    throw DeltaCodecError("delta buffer has " + std::to_string(cloud->num_attributes()) +
                          " attributes, expected 1");
  }
  const draco::PointAttribute* att = cloud->attribute(0);
  if (att == nullptr || att->buffer() == nullptr) {
    throw DeltaCodecError("delta buffer has no attribute data");
  }
  if (att->num_components() != 3 || att->data_type() != draco::DT_FLOAT32) {
    throw DeltaCodecError("delta attribute is not float32×3 (" + std::to_string(att->num_components()) +
                          " components of Draco type " + std::to_string(att->data_type()) + ")");
  }
  // Every value index we will read must lie inside the attribute's storage.
  const std::size_t entries = att->size();
  const std::int64_t stride = att->byte_stride();
  const std::int64_t offset = att->byte_offset();
  if (stride < static_cast<std::int64_t>(3 * sizeof(float)) || offset < 0 ||
      static_cast<std::uint64_t>(offset) + static_cast<std::uint64_t>(stride) * entries >
          static_cast<std::uint64_t>(att->buffer()->data_size())) {
    throw DeltaCodecError("delta attribute storage is inconsistent with its size");
  }
  if (!att->is_mapping_identity() && att->indices_map_size() < count) {
    throw DeltaCodecError("delta attribute maps fewer points than the buffer holds");
  }

  const bool identity = att->is_mapping_identity();
  const auto* data = att->buffer()->data();
  for (std::uint32_t i = 0; i < count; ++i) {
    const std::size_t avi = identity ? i : att->mapped_index(draco::PointIndex(i)).value();
    if (avi >= entries) throw DeltaCodecError("delta attribute has no value for point " + std::to_string(i));
    float value[3];
    std::memcpy(value, data + offset + stride * static_cast<std::int64_t>(avi), sizeof value);
    // encode_deltas never writes a non-finite value: this buffer is corrupt.
    if (!std::isfinite(value[0]) || !std::isfinite(value[1]) || !std::isfinite(value[2])) {
      throw DeltaCodecError("delta buffer decodes to a non-finite value at point " + std::to_string(i));
    }
    std::memcpy(&out[3 * static_cast<std::size_t>(i)], value, sizeof value);
  }
}


}  // namespace

void throw_implausible_delta(double d, std::size_t vertex) {
  if (!std::isfinite(d)) throw DeltaCodecError("delta of vertex " + std::to_string(vertex) + " is not finite");
  throw DeltaCodecError("delta of vertex " + std::to_string(vertex) + " is implausibly large (|" + std::to_string(d) + "| > 1e30)");
}

EncodedDeltas encode_deltas(const std::vector<Vec3>& deltas, std::uint32_t bits) {
  if (bits < kMinBits || bits > kMaxBits) {
    throw DeltaCodecError("quantization bits must be in " + std::to_string(kMinBits) + "…" +
                          std::to_string(kMaxBits) + ", got " + std::to_string(bits));
  }
  // Draco counts points in int32.
  if (deltas.size() > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())) {
    throw DeltaCodecError("too many deltas for one Draco buffer: " + std::to_string(deltas.size()));
  }
  const auto n = static_cast<std::uint32_t>(deltas.size());

  // Validate, convert to float32 (what Draco stores) and find the range.
  std::vector<float> values(3 * static_cast<std::size_t>(n));
  bool all_zero = true;
  for (std::uint32_t i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      const double d = deltas[i][c];
      check_delta(d, i);
      if (d != 0.0) all_zero = false;
      values[3 * static_cast<std::size_t>(i) + c] = static_cast<float>(d);
    }
  }

  EncodedDeltas result;
  result.count = n;
  result.bits = bits;
  if (all_zero) return result;  // empty bytes, min = range = max_error = 0

  const DeltaQuantization q = quantization_over(values, bits);
  result.bytes = encode_draco(values, q);
  result.min = q.min;
  result.range = q.range;

  // What a decoder will read, against the input (the doubles, so the float32
  // conversion counts as error too).
  q.decode(values, values);
  double max_error = 0.0;
  for (std::uint32_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c)
      max_error = std::max(max_error, std::abs(double{values[3 * static_cast<std::size_t>(i) + c]} - deltas[i][c]));
  result.max_error = float_at_least(max_error);  // reported ≥ actual
  return result;
}

void decode_deltas_into(std::string_view bytes, std::uint32_t count, std::span<float> out) {
  if (out.size() != 3 * static_cast<std::size_t>(count))
    throw DeltaCodecError("delta output holds " + std::to_string(out.size()) + " floats for " + std::to_string(count) +
                          " points");
  if (bytes.empty()) {
    std::fill(out.begin(), out.end(), 0.0f);
    return;
  }
  decode_draco(bytes, count, out);
}

std::vector<Vec3> decode_deltas(const EncodedDeltas& encoded) {
  // The count is checked against the buffer before anything is allocated for it.
  if (!encoded.bytes.empty()) check_header(encoded.bytes, encoded.count);
  std::vector<float> values(3 * static_cast<std::size_t>(encoded.count));
  decode_deltas_into(encoded.bytes, encoded.count, values);
  std::vector<Vec3> out(encoded.count);
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = Vec3(values[3 * i], values[3 * i + 1], values[3 * i + 2]);
  return out;
}

}  // namespace filigree
