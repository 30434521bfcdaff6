// Pose files: the raw float32 `.pose` format and posed base meshes.

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unistd.h>

#include "mesh/mesh_io.h"
#include "runtime/pose_io.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// Unique per test and per process, so parallel runs never share a file.
std::filesystem::path temp_file(const std::string& name) {
  const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
  return std::filesystem::path(::testing::TempDir()) /
         ("filigree_pose_io_" + std::to_string(::getpid()) + "_" + test->name() + "_" + name);
}

void write_bytes(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.flush()) << path;
}

std::string read_bytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

template <typename F>
std::string pose_error_of(F&& f) {
  try {
    f();
  } catch (const PoseError& e) {
    return e.what();
  }
  return "(no PoseError)";
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(PoseIo, BinaryRoundTripIsExactForFloatValues) {
  Pose pose;
  pose.positions = {{1.0, -2.5, 0.1f}, {1e-30f, 65504.0, -0.0}, {3.0e38f, 1.0f / 3.0f, 7.0}};
  const auto path = temp_file("round_trip.pose");
  write_pose(pose, path);
  EXPECT_EQ(std::filesystem::file_size(path), 12u * pose.positions.size());
  // Little-endian float32: 1.0f is 0x3f800000.
  EXPECT_EQ(read_bytes(path).substr(0, 4), std::string("\x00\x00\x80\x3f", 4));
  const Pose back = read_pose(path, pose.positions.size());
  EXPECT_EQ(back.positions, pose.positions);
  std::filesystem::remove(path);
}

TEST(PoseIo, WrongFileSizeNamesTheByteCounts) {
  const auto path = temp_file("short.pose");
  write_bytes(path, std::string(40, '\0'));
  const std::string message = pose_error_of([&] { read_pose(path, 3); });
  EXPECT_TRUE(contains(message, path.string())) << message;
  EXPECT_TRUE(contains(message, "40 bytes")) << message;
  EXPECT_TRUE(contains(message, "36")) << message;
  std::filesystem::remove(path);
}

TEST(PoseIo, NaNInTheFileIsAnError) {
  Pose pose;
  pose.positions = {{0, 0, 0}, {1, 1, 1}};
  const auto path = temp_file("nan.pose");
  write_pose(pose, path);
  std::string bytes = read_bytes(path);
  bytes.replace(12 + 4, 4, std::string("\x00\x00\xc0\x7f", 4));  // vertex 1, y: a quiet NaN
  write_bytes(path, bytes);
  const std::string message = pose_error_of([&] { read_pose(path, 2); });
  EXPECT_TRUE(contains(message, path.string())) << message;
  EXPECT_TRUE(contains(message, "position 1")) << message;
  std::filesystem::remove(path);
}

TEST(PoseIo, MeshFilesGiveTheirPositions) {
  const auto obj = temp_file("posed.obj");
  write_bytes(obj, "v 1 2 3\nv 0.5 -0.25 4\nv 0 0 1\nf 1 2 3\n");
  const Pose pose = read_pose(obj, 3);
  const std::vector<Vec3> expected = {{1, 2, 3}, {0.5, -0.25, 4}, {0, 0, 1}};
  EXPECT_EQ(pose.positions, expected);
  std::filesystem::remove(obj);

  // As `filigree export-base` writes it: binary PLY keeps doubles exactly.
  const TriMesh base = test::icosphere(1);
  const auto ply = temp_file("posed.ply");
  write_mesh(base, ply);
  EXPECT_EQ(read_pose(ply, base.vertex_count()).positions, base.positions);
  std::filesystem::remove(ply);
}

TEST(PoseIo, WrongVertexCountInAMeshIsAnError) {
  const auto path = temp_file("three.obj");
  write_bytes(path, "v 1 2 3\nv 0.5 -0.25 4\nv 0 0 1\nf 1 2 3\n");
  const std::string message = pose_error_of([&] { read_pose(path, 4); });
  EXPECT_TRUE(contains(message, path.string())) << message;
  EXPECT_TRUE(contains(message, "3 positions")) << message;
  EXPECT_TRUE(contains(message, "4 vertices")) << message;
  std::filesystem::remove(path);
}

TEST(PoseIo, UnreadableFilesAreErrors) {
  const auto missing = temp_file("missing.pose");
  EXPECT_TRUE(contains(pose_error_of([&] { read_pose(missing, 1); }), missing.string()));
  const auto garbage = temp_file("garbage.obj");
  write_bytes(garbage, "this is not a mesh\n");
  EXPECT_TRUE(contains(pose_error_of([&] { read_pose(garbage, 1); }), garbage.string()));
  std::filesystem::remove(garbage);
  const auto unknown = temp_file("pose.txt");
  write_bytes(unknown, "1 2 3\n");
  EXPECT_TRUE(contains(pose_error_of([&] { read_pose(unknown, 1); }), "'.txt'"));
  std::filesystem::remove(unknown);
}

TEST(PoseIo, OnlyPoseFilesOfFloat32ValuesAreWritten) {
  Pose pose;
  pose.positions = {{0, 0, 0}};
  const auto obj = temp_file("out.obj");
  EXPECT_TRUE(contains(pose_error_of([&] { write_pose(pose, obj); }), ".pose"));
  EXPECT_FALSE(std::filesystem::exists(obj));

  pose.positions[0].x() = 1e300;
  EXPECT_TRUE(contains(pose_error_of([&] { write_pose(pose, temp_file("huge.pose")); }), "position 0"));
  pose.positions[0].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_TRUE(contains(pose_error_of([&] { write_pose(pose, temp_file("nan.pose")); }), "position 0"));
}

}  // namespace
}  // namespace filigree
