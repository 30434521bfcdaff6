#include "codec/level_mesh_codec.h"

#include <memory>

#include <draco/attributes/geometry_attribute.h>
#include <draco/attributes/point_attribute.h>
#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

#include "codec/delta_codec.h"

namespace filigree {

std::string encode_level_mesh(const LevelMesh& level) {
  const auto n = static_cast<std::uint32_t>(level.original_ids.size());
  draco::Mesh mesh;
  mesh.set_num_points(n);
  draco::GeometryAttribute ga;
  ga.Init(draco::GeometryAttribute::GENERIC, nullptr, 1, draco::DT_UINT32, false, sizeof(std::uint32_t), 0);
  const int att = mesh.AddAttribute(ga, /*identity_mapping=*/true, n);
  draco::PointAttribute* ids = mesh.attribute(att);
  for (std::uint32_t i = 0; i < n; ++i) ids->SetAttributeValue(draco::AttributeValueIndex(i), &level.original_ids[i]);
  const std::size_t triangles = level.faces.size() / 3;
  mesh.SetNumFaces(triangles);
  for (std::size_t f = 0; f < triangles; ++f) {
    draco::Mesh::Face face;
    for (int k = 0; k < 3; ++k) face[k] = draco::PointIndex(level.faces[3 * f + k]);
    mesh.SetFace(draco::FaceIndex(static_cast<std::uint32_t>(f)), face);
  }
  draco::Encoder encoder;
  // Sequential: edgebreaker would reorder the vertices, and the frames'
  // deltas are in the level's vertex order.
  encoder.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
  encoder.SetSpeedOptions(5, 5);
  draco::EncoderBuffer out;
  const draco::Status status = encoder.EncodeMeshToBuffer(mesh, &out);
  if (!status.ok()) throw DeltaCodecError("Draco could not encode the level's mesh: " + status.error_msg_string());
  return std::string(out.data(), out.size());
}

LevelMesh decode_level_mesh(std::string_view bytes, std::uint32_t vertex_limit) {
  draco::DecoderBuffer buffer;
  buffer.Init(bytes.data(), bytes.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) throw DeltaCodecError("a level's mesh is no Draco mesh: " + decoded.status().error_msg_string());
  const std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
  const draco::PointAttribute* ids = mesh->GetNamedAttribute(draco::GeometryAttribute::GENERIC);
  if (ids == nullptr || ids->data_type() != draco::DT_UINT32 || ids->num_components() != 1)
    throw DeltaCodecError("a level's mesh has no UINT32 attribute of original ids");
  LevelMesh level;
  const std::uint32_t n = mesh->num_points();
  level.original_ids.resize(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    ids->GetMappedValue(draco::PointIndex(i), &level.original_ids[i]);
    if (level.original_ids[i] >= vertex_limit || (i > 0 && level.original_ids[i] <= level.original_ids[i - 1]))
      throw DeltaCodecError("a level's original ids must ascend below " + std::to_string(vertex_limit) + ": vertex " +
                            std::to_string(i) + " has " + std::to_string(level.original_ids[i]));
  }
  level.faces.resize(3 * static_cast<std::size_t>(mesh->num_faces()));
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
    const draco::Mesh::Face& face = mesh->face(f);
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = face[k].value();
      if (v >= n) throw DeltaCodecError("a level's face indexes vertex " + std::to_string(v) + " of " + std::to_string(n));
      level.faces[3 * f.value() + k] = v;
    }
  }
  return level;
}

}  // namespace filigree
