// The hierarchy file: bit-identical round trips, and every kind of damage
// turned into an error that says what is wrong.

#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "preprocess/preprocess.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

class HierarchyFileTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    PreprocessOptions options;
    options.base_vertices = 60;
    hierarchy_ = new Hierarchy(preprocess(test::shipped_mesh("head_open.off"), options));
    bytes_ = new std::string(serialize_hierarchy(*hierarchy_));
  }
  static void TearDownTestSuite() {
    delete hierarchy_;
    delete bytes_;
  }
  static std::string error_of(const std::string& bytes) {
    try {
      deserialize_hierarchy(bytes, "test.fgh");
    } catch (const HierarchyFileError& e) {
      return e.what();
    }
    return "no error";
  }
  static std::filesystem::path temp_file(const std::string& name) {
    return std::filesystem::path(::testing::TempDir()) / ("filigree_" + std::to_string(::getpid()) + "_" + name);
  }
  static inline Hierarchy* hierarchy_ = nullptr;
  static inline std::string* bytes_ = nullptr;
};

TEST_F(HierarchyFileTest, MemoryRoundTripIsBitIdentical) {
  const Hierarchy back = deserialize_hierarchy(*bytes_);
  EXPECT_EQ(serialize_hierarchy(back), *bytes_);
  EXPECT_EQ(back.rest_positions, hierarchy_->rest_positions);
  EXPECT_EQ(back.faces, hierarchy_->faces);
  EXPECT_EQ(back.parents, hierarchy_->parents);
  EXPECT_EQ(back.maps_bary, hierarchy_->maps_bary);
  EXPECT_EQ(back.mesh_hash, hierarchy_->mesh_hash);
  EXPECT_EQ(back.build.build_seconds, hierarchy_->build.build_seconds);
}

TEST_F(HierarchyFileTest, FileRoundTripIsBitIdentical) {
  const auto path = temp_file("roundtrip.fgh");
  save_hierarchy(*hierarchy_, path);
  std::ifstream in(path, std::ios::binary);
  const std::string on_disk((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(on_disk, *bytes_);
  const Hierarchy back = load_hierarchy(path);
  EXPECT_EQ(serialize_hierarchy(back), *bytes_);
  const HierarchyFileInfo info = read_hierarchy_file_info(path);
  EXPECT_EQ(info.version, kHierarchyFormatVersion);
  EXPECT_EQ(info.mesh_hash, hierarchy_->mesh_hash);
  EXPECT_EQ(info.vertex_count, hierarchy_->vertex_count());
  EXPECT_EQ(info.node_count, hierarchy_->node_count());
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".partial"));
  std::filesystem::remove(path);
}

TEST_F(HierarchyFileTest, TruncatedFilesAreReportedAsTruncated) {
  for (std::size_t size : {std::size_t{0}, std::size_t{8}, std::size_t{63}, std::size_t{64}, std::size_t{200},
                           bytes_->size() / 2, bytes_->size() - 1}) {
    const std::string msg = error_of(bytes_->substr(0, size));
    EXPECT_NE(msg.find("truncated"), std::string::npos) << "size " << size << ": " << msg;
    EXPECT_NE(msg.find("test.fgh"), std::string::npos) << msg;
  }
}

TEST_F(HierarchyFileTest, WrongMagicVersionAndTrailingBytes) {
  std::string b = *bytes_;
  b[0] = 'X';
  EXPECT_NE(error_of(b).find("bad magic"), std::string::npos);
  EXPECT_NE(error_of("hello, this is not a hierarchy file at all, not even close to one....").find("bad magic"), std::string::npos);

  b = *bytes_;
  const std::uint32_t future = kHierarchyFormatVersion + 1;
  std::memcpy(b.data() + 8, &future, 4);
  EXPECT_NE(error_of(b).find("unsupported format version 2"), std::string::npos) << error_of(b);

  EXPECT_NE(error_of(*bytes_ + "junk").find("unexpected bytes"), std::string::npos);
}

TEST_F(HierarchyFileTest, EveryFlippedPayloadByteIsCaught) {
  // Flip bytes spread over the whole payload; each must be an error, never a
  // crash or a silently different hierarchy.
  const std::size_t step = std::max<std::size_t>(bytes_->size() / 97, 1);
  for (std::size_t at = 64; at < bytes_->size(); at += step) {
    std::string b = *bytes_;
    b[at] = static_cast<char>(b[at] ^ 0x5A);
    EXPECT_NE(error_of(b).find("corrupt"), std::string::npos) << "byte " << at;
  }
}

TEST_F(HierarchyFileTest, ForgedFileWithValidChecksumFailsValidation) {
  // A structurally wrong hierarchy written by a buggy or malicious producer:
  // the checksum is right, the content is not.
  Hierarchy forged = *hierarchy_;
  forged.parents[0] = static_cast<NodeId>(forged.node_count() + 5);
  std::string msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("corrupt: invalid hierarchy"), std::string::npos) << msg;

  forged = *hierarchy_;
  forged.faces[3][1] = static_cast<Index>(forged.vertex_count());
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("face 3"), std::string::npos) << msg;

  forged = *hierarchy_;
  forged.maps_bary[7] = Vec3(0.5, 0.5, 0.5);
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("barycentric"), std::string::npos) << msg;

  forged = *hierarchy_;
  forged.ring_weights[2] = std::nan("");
  EXPECT_NE(error_of(serialize_hierarchy(forged)).find("ring weight"), std::string::npos);
}

TEST_F(HierarchyFileTest, MissingFileIsAnError) {
  EXPECT_THROW(load_hierarchy(temp_file("does_not_exist.fgh")), HierarchyFileError);
}

}  // namespace
}  // namespace filigree
