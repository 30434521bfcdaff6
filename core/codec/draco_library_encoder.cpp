#include "codec/draco_library_encoder.h"

#include <cstdint>
#include <memory>

#include <draco/attributes/geometry_attribute.h>
#include <draco/compression/config/compression_shared.h>
#include <draco/compression/expert_encode.h>
#include <draco/core/encoder_buffer.h>
#include <draco/point_cloud/point_cloud.h>
#include <draco/point_cloud/point_cloud_builder.h>

#include "codec/delta_codec.h"

namespace filigree {

std::string encode_with_draco_library(std::span<const float> values, const DeltaQuantization& q, int speed) {
  if (values.empty()) return {};
  const auto n = static_cast<std::uint32_t>(values.size() / 3);
  draco::PointCloudBuilder builder;
  builder.Start(n);
  const int att_id = builder.AddAttribute(draco::GeometryAttribute::GENERIC, 3, draco::DT_FLOAT32);
  // Point i gets values[3i … 3i+2]; Finalize(false) merges no points, and
  // the sequential method keeps their order (TOOLCHAIN "Draco").
  builder.SetAttributeValuesForAllPoints(att_id, values.data(), 3 * sizeof(float));
  const std::unique_ptr<draco::PointCloud> cloud = builder.Finalize(/*deduplicate_points=*/false);
  if (!cloud || cloud->num_points() != n) throw DeltaCodecError("Draco could not build the delta point cloud");

  draco::ExpertEncoder encoder(*cloud);
  encoder.SetEncodingMethod(draco::POINT_CLOUD_SEQUENTIAL_ENCODING);
  encoder.SetSpeedOptions(speed, speed);
  const float origin[3] = {q.min, q.min, q.min};
  encoder.SetAttributeExplicitQuantization(att_id, static_cast<int>(q.bits), 3, origin, q.range);
  draco::EncoderBuffer out;
  const draco::Status status = encoder.EncodeToBuffer(&out);
  if (!status.ok()) throw DeltaCodecError("Draco could not encode the deltas: " + status.error_msg_string());
  return std::string(out.data(), out.size());
}

}  // namespace filigree
