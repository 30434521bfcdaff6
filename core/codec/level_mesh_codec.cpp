#include "codec/level_mesh_codec.h"

#include <algorithm>
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
  ga.Init(draco::GeometryAttribute::POSITION, nullptr, 1, draco::DT_UINT32, false, sizeof(std::uint32_t), 0);
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
  // Edgebreaker reorders the points; each carries its original id, and the
  // level's order is ascending id, so the decoder sorts them back.
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  encoder.SetSpeedOptions(0, 0);
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
  const draco::PointAttribute* ids = mesh->GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (ids == nullptr || ids->data_type() != draco::DT_UINT32 || ids->num_components() != 1)
    throw DeltaCodecError("a level's mesh has no UINT32 attribute of original ids");
  // The level's vertices are the distinct ids, ascending; a point's index
  // in them is its vertex (Draco may split a vertex into several points).
  const std::uint32_t points = mesh->num_points();
  std::vector<std::uint32_t> id_of(points);
  for (std::uint32_t i = 0; i < points; ++i) {
    ids->GetMappedValue(draco::PointIndex(i), &id_of[i]);
    if (id_of[i] >= vertex_limit)
      throw DeltaCodecError("a level's vertex has original id " + std::to_string(id_of[i]) + ", past the mesh's " +
                            std::to_string(vertex_limit) + " vertices");
  }
  LevelMesh level;
  level.original_ids = id_of;
  std::sort(level.original_ids.begin(), level.original_ids.end());
  level.original_ids.erase(std::unique(level.original_ids.begin(), level.original_ids.end()), level.original_ids.end());
  const auto vertex_of = [&](std::uint32_t point) {
    return static_cast<std::uint32_t>(std::lower_bound(level.original_ids.begin(), level.original_ids.end(), id_of[point]) -
                                      level.original_ids.begin());
  };
  level.faces.resize(3 * static_cast<std::size_t>(mesh->num_faces()));
  for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f) {
    const draco::Mesh::Face& face = mesh->face(f);
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t p = face[k].value();
      if (p >= points) throw DeltaCodecError("a level's face indexes point " + std::to_string(p) + " of " + std::to_string(points));
      level.faces[3 * f.value() + k] = vertex_of(p);
    }
  }
  return level;
}

}  // namespace filigree
