#include "runtime/pose_io.h"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <string>
#include <system_error>

#include "mesh/mesh_io.h"

namespace filigree {
namespace {

constexpr std::size_t kBytesPerVertex = 3 * sizeof(float);
static_assert(sizeof(float) == 4 && std::numeric_limits<float>::is_iec559);

[[noreturn]] void fail(const std::filesystem::path& path, const std::string& reason) {
  throw PoseError("pose file " + path.string() + ": " + reason);
}

std::string lowercase_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool is_mesh_extension(const std::string& ext) {
  return ext == ".obj" || ext == ".ply" || ext == ".off" || ext == ".gltf" || ext == ".glb";
}

// Byte by byte, so the file is little-endian whatever the host is.
float load_float(const unsigned char* p) {
  return std::bit_cast<float>(std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 |
                              std::uint32_t{p[3]} << 24);
}

void append_float(std::string& out, float value) {
  const auto bits = std::bit_cast<std::uint32_t>(value);
  for (int shift = 0; shift < 32; shift += 8) out.push_back(static_cast<char>((bits >> shift) & 0xffu));
}

Pose read_binary(const std::filesystem::path& path, std::size_t base_vertex_count) {
  // Size first: a wrong file is reported without reading (or allocating) it.
  std::error_code error;
  const std::uintmax_t size = std::filesystem::file_size(path, error);
  if (error) fail(path, "cannot read: " + error.message());
  const std::size_t expected = kBytesPerVertex * base_vertex_count;
  if (size != expected)
    throw PoseError("pose file " + path.string() + " has " + std::to_string(size) + " bytes; a pose of " +
                    std::to_string(base_vertex_count) + " base vertices needs 12·" + std::to_string(base_vertex_count) +
                    " = " + std::to_string(expected));
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, std::string("cannot open: ") + std::strerror(errno));
  std::string bytes(expected, '\0');
  if (!in.read(bytes.data(), static_cast<std::streamsize>(expected))) fail(path, "read failed");

  Pose pose;
  pose.positions.resize(base_vertex_count);
  const auto* p = reinterpret_cast<const unsigned char*>(bytes.data());
  for (Vec3& x : pose.positions) {
    x = Vec3(load_float(p), load_float(p + 4), load_float(p + 8));
    p += kBytesPerVertex;
  }
  return pose;
}

Pose read_mesh_pose(const std::filesystem::path& path) {
  try {
    return Pose{read_mesh(path).positions};
  } catch (const MeshIoError& e) {
    throw PoseError(std::string("cannot read pose: ") + e.what());
  }
}

}  // namespace

Pose read_pose(const std::filesystem::path& path, std::size_t base_vertex_count) {
  const std::string ext = lowercase_extension(path);
  Pose pose;
  if (ext == ".pose")
    pose = read_binary(path, base_vertex_count);
  else if (is_mesh_extension(ext))
    pose = read_mesh_pose(path);
  else
    fail(path, (ext.empty() ? std::string("no file extension") : "unsupported format '" + ext + "'") +
                   " (a pose is a .pose file of float32 triples or a mesh file: .obj .ply .off .gltf .glb)");
  try {
    validate_pose(pose, base_vertex_count);
  } catch (const PoseError& e) {
    fail(path, e.what());
  }
  return pose;
}

void write_pose(const Pose& pose, const std::filesystem::path& path) {
  const std::string ext = lowercase_extension(path);
  if (ext != ".pose") fail(path, "poses are written only as .pose (raw float32), not '" + ext + "'");
  std::string bytes;
  bytes.reserve(kBytesPerVertex * pose.positions.size());
  constexpr double kFloatMax = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < pose.positions.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const double value = pose.positions[i][k];
      // Checked before the cast: an out-of-range double-to-float conversion is undefined.
      if (!(std::abs(value) <= kFloatMax))
        fail(path, "position " + std::to_string(i) + " is not finite or does not fit in float32");
      append_float(bytes, static_cast<float>(value));
    }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) fail(path, std::string("cannot open for writing: ") + std::strerror(errno));
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out.flush()) fail(path, std::string("write failed: ") + std::strerror(errno));
}

}  // namespace filigree
