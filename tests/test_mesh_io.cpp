// Tests for mesh_io: round trips, format details, glTF scenes and malformed input.

#include <gtest/gtest.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "mesh/json_nesting.h"
#include "mesh/mesh_io.h"

namespace filigree {
namespace {

namespace fs = std::filesystem;

const fs::path kDataDir = FILIGREE_TEST_DATA_DIR;

// Each test gets its own empty directory.
class MeshIoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string test = ::testing::UnitTest::GetInstance()->current_test_info()->name();
    dir_ = fs::path(::testing::TempDir()) / ("filigree_mesh_io_" + std::to_string(::getpid()) + "_" + test);
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path path(const std::string& file) const { return dir_ / file; }

  fs::path dir_;
};

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Coordinates that float cannot represent, and a face order that is not sorted.
TriMesh awkward_mesh() {
  TriMesh mesh;
  mesh.positions = {Vec3(0.1, 1.0 / 3.0, -2.718281828459045),
                    Vec3(1e-7, 12345.678901234567, 0.30000000000000004),
                    Vec3(-0.0, 5.5, 1e10 / 7.0),
                    Vec3(7.0 / 9.0, -1.0 / 11.0, 2.0 / 13.0)};
  mesh.faces = {{2, 0, 1}, {3, 1, 0}, {0, 2, 3}, {1, 3, 2}};
  return mesh;
}

void expect_same_mesh(const TriMesh& expected, const TriMesh& actual, double tolerance) {
  ASSERT_EQ(expected.vertex_count(), actual.vertex_count());
  ASSERT_EQ(expected.face_count(), actual.face_count());
  for (std::size_t v = 0; v < expected.vertex_count(); ++v) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(expected.positions[v][k], actual.positions[v][k],
                  tolerance * std::max(1.0, std::abs(expected.positions[v][k])))
          << "vertex " << v << " coordinate " << k;
    }
  }
  for (std::size_t f = 0; f < expected.face_count(); ++f) EXPECT_EQ(expected.faces[f], actual.faces[f]) << "face " << f;
}

TEST_F(MeshIoTest, ObjRoundTripIsExact) {
  const TriMesh mesh = awkward_mesh();
  write_mesh(mesh, path("m.obj"));
  const TriMesh back = read_mesh(path("m.obj"));
  expect_same_mesh(mesh, back, 1e-12);
  EXPECT_EQ(mesh.positions, back.positions);  // shortest round-trip digits: bit exact
}

TEST_F(MeshIoTest, PlyRoundTripIsExactBinaryLittleEndian) {
  const TriMesh mesh = awkward_mesh();
  write_mesh(mesh, path("m.PLY"));
  EXPECT_TRUE(read_bytes(path("m.PLY")).starts_with("ply\nformat binary_little_endian 1.0\n"));
  const TriMesh back = read_mesh(path("m.PLY"));
  expect_same_mesh(mesh, back, 1e-12);
  EXPECT_EQ(mesh.positions, back.positions);
}

TEST_F(MeshIoTest, GlbRoundTrip) {
  const TriMesh mesh = awkward_mesh();
  write_mesh(mesh, path("m.glb"));
  EXPECT_TRUE(read_bytes(path("m.glb")).starts_with("glTF"));
  expect_same_mesh(mesh, read_mesh(path("m.glb")), 1e-6);
}

TEST_F(MeshIoTest, ReadFromMemoryMatchesFile) {
  const TriMesh mesh = awkward_mesh();
  for (const std::string format : {"obj", "ply", "glb"}) {
    const fs::path file = path("m." + format);
    write_mesh(mesh, file);
    const TriMesh from_file = read_mesh(file);
    expect_same_mesh(from_file, read_mesh_from_memory(read_bytes(file), "." + format), 0.0);
  }
  EXPECT_EQ(read_mesh_from_memory("\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "OBJ").face_count(), 1u);
}

TEST_F(MeshIoTest, ReadsShippedFiles) {
  const TriMesh bunny = read_mesh(kDataDir / "bunny_small.obj");
  EXPECT_EQ(bunny.vertex_count(), 1839u);
  EXPECT_EQ(bunny.face_count(), 3674u);
  EXPECT_DOUBLE_EQ(bunny.positions[0].x(), 1.301895);
  const TriMesh head = read_mesh(kDataDir / "head_open.off");
  EXPECT_EQ(head.vertex_count(), 1487u);
  EXPECT_EQ(head.face_count(), 2918u);
  EXPECT_DOUBLE_EQ(head.positions[0].y(), 6.592999);
  EXPECT_EQ(head.faces.back(), (Triangle{1459, 1113, 1145}));
}

TEST_F(MeshIoTest, ObjKeepsEveryFaceAsStored) {
  const std::string obj =
      "# comment\r\n"
      "mtllib x.mtl\n"
      "o thing\n"
      "v 0 0 0\nv 1 0 0\nv 1 1 0  # trailing comment\nv 0 1 0\n"
      "vt 0 0\nvn 0 0 1\n"
      "usemtl m\ns off\n"
      "f 1/1/1 2/1/1 3/1/1 4/1/1\n"  // quad: fan-triangulated
      "f 1 1 2\n"                      // degenerate: kept for validate_mesh
      "f 1 2 99\n"                     // out of range: kept for validate_mesh
      "f -1 -2 -3\n"                   // relative references
      "f 1//1 +3//1 4//1\r\n";
  const TriMesh mesh = read_mesh_from_memory(obj, "obj");
  ASSERT_EQ(mesh.vertex_count(), 4u);
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {0, 0, 1}, {0, 1, 98}, {3, 2, 1}, {0, 2, 3}};
  EXPECT_EQ(mesh.faces, expected);
}

TEST_F(MeshIoTest, OffVariants) {
  const std::string off =
      "COFF\n# colours follow the coordinates\n"
      "5 3 0\n"
      "0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n1 1 0 0 0 0 255\n0 1 0 1 1 1 1\n0.5 0.5 1e-3 0 0 0 0\n"
      "4 0 1 2 3 255 0 0\n"
      "3 0 1 99\n"
      "3 4 4 1\n";
  const TriMesh mesh = read_mesh_from_memory(off, "off");
  ASSERT_EQ(mesh.vertex_count(), 5u);
  EXPECT_DOUBLE_EQ(mesh.positions[4].z(), 1e-3);
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {0, 1, 99}, {4, 4, 1}};
  EXPECT_EQ(mesh.faces, expected);

  const TriMesh same_line = read_mesh_from_memory("OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n", "off");
  EXPECT_EQ(same_line.face_count(), 1u);
  const TriMesh homogeneous = read_mesh_from_memory("4OFF\n3 1 0\n2 4 6 2\n1 0 0 1\n0 1 0 1\n3 0 1 2\n", "off");
  EXPECT_EQ(homogeneous.positions[0], Vec3(1, 2, 3));
}

TEST_F(MeshIoTest, PlyAsciiWithExtraElementsAndProperties) {
  const std::string ply =
      "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\n"
      "element vertex 4\r\nproperty float nx\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\n"
      "property list uchar int junk\r\n"
      "element face 2\r\nproperty uchar flags\r\nproperty list uchar int vertex_index\r\n"
      "element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\n"
      "end_header\r\n"
      "9 0 0 0 2 7 7\r\n9 1 0 0 0\r\n9 1 1 0.30000000000000004 0\r\n9 0 1 0 1 5\r\n"
      "1 4 0 1 2 3\r\n0 3 0 1 7\r\n"
      "0 1\r\n";
  const TriMesh mesh = read_mesh_from_memory(ply, "ply");
  ASSERT_EQ(mesh.vertex_count(), 4u);
  EXPECT_EQ(mesh.positions[2], Vec3(1, 1, 0.30000000000000004));
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {0, 1, 7}};
  EXPECT_EQ(mesh.faces, expected);
}

// Found by fuzzing: an element without properties takes no bytes, however
// many entries it claims (10^11 of them used to be looped over one by one).
TEST_F(MeshIoTest, PlyElementWithoutPropertiesTakesNothing) {
  const std::string ply =
      "ply\nformat ascii 1.0\nelement note 77777777777\n"
      "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const TriMesh mesh = read_mesh_from_memory(ply, "ply");
  EXPECT_EQ(mesh.vertex_count(), 3u);
  EXPECT_EQ(mesh.face_count(), 1u);
}

TEST_F(MeshIoTest, PlyBinaryBigEndianFloat) {
  std::string ply =
      "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
  auto put_be = [&ply](const void* value, std::size_t size) {
    const auto* bytes = static_cast<const unsigned char*>(value);
    for (std::size_t i = 0; i < size; ++i) ply += static_cast<char>(bytes[size - 1 - i]);  // host is little-endian
  };
  for (const float x : {0.5f, 0.0f, 0.0f, 1.0f, 2.0f, 0.0f, -3.0f, 0.25f, 8.0f}) put_be(&x, 4);
  ply += '\x03';
  for (const std::uint32_t i : {2u, 1u, 0u}) put_be(&i, 4);
  const TriMesh mesh = read_mesh_from_memory(ply, "ply");
  ASSERT_EQ(mesh.vertex_count(), 3u);
  EXPECT_EQ(mesh.positions[2], Vec3(-3.0, 0.25, 8.0));
  EXPECT_EQ(mesh.faces, (std::vector<Triangle>{{2, 1, 0}}));
}

// --- glTF -------------------------------------------------------------------

// Appends raw bytes to the model's single buffer and a bufferView over them.
int add_view(tinygltf::Model& model, const void* data, std::size_t size, std::size_t stride = 0) {
  if (model.buffers.empty()) model.buffers.emplace_back();
  std::vector<unsigned char>& buffer = model.buffers[0].data;
  while (buffer.size() % 4 != 0) buffer.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buffer.size();
  view.byteLength = size;
  view.byteStride = stride;
  const auto* bytes = static_cast<const unsigned char*>(data);
  buffer.insert(buffer.end(), bytes, bytes + size);
  model.bufferViews.push_back(view);
  return static_cast<int>(model.bufferViews.size() - 1);
}

int add_accessor(tinygltf::Model& model, int view, int component_type, int type, std::size_t count,
                 std::size_t offset = 0) {
  tinygltf::Accessor accessor;
  accessor.bufferView = view;
  accessor.byteOffset = offset;
  accessor.componentType = component_type;
  accessor.type = type;
  accessor.count = count;
  model.accessors.push_back(accessor);
  return static_cast<int>(model.accessors.size() - 1);
}

int add_positions(tinygltf::Model& model, const std::vector<float>& xyz) {
  const int view = add_view(model, xyz.data(), xyz.size() * sizeof(float));
  const int accessor = add_accessor(model, view, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, xyz.size() / 3);
  std::vector<double> lo(3, 1e30), hi(3, -1e30);
  for (std::size_t i = 0; i < xyz.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], double{xyz[i]});
    hi[i % 3] = std::max(hi[i % 3], double{xyz[i]});
  }
  model.accessors[accessor].minValues = lo;
  model.accessors[accessor].maxValues = hi;
  return accessor;
}

tinygltf::Primitive primitive(int positions, int indices, int mode) {
  tinygltf::Primitive p;
  p.attributes["POSITION"] = positions;
  p.indices = indices;
  p.mode = mode;
  return p;
}

// Node 0 (translation (1,2,3), scale 2) instances mesh 0: a TRIANGLES
// primitive with ushort indices and a TRIANGLE_STRIP primitive with interleaved
// positions (stride 24) and no indices. Its child node 1 (mirror x) instances
// mesh 1, one triangle, whose winding must be flipped.
tinygltf::Model two_primitive_model() {
  tinygltf::Model model;
  model.asset.version = "2.0";
  const int tri_positions = add_positions(model, {0, 0, 0, 1, 0, 0, 0, 1, 0});
  const std::uint16_t tri_indices[] = {0, 1, 2};
  const int tri_index_view = add_view(model, tri_indices, sizeof tri_indices);
  const int tri_index_accessor =
      add_accessor(model, tri_index_view, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, 3);

  // Strip of 4 vertices, each followed by 3 unrelated floats.
  const float strip[] = {0, 0, 1, 9, 9, 9, 1, 0, 1, 9, 9, 9, 0, 1, 1, 9, 9, 9, 1, 1, 1, 9, 9, 9};
  const int strip_view = add_view(model, strip, sizeof strip, 24);
  const int strip_accessor = add_accessor(model, strip_view, TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, 4);
  model.accessors[strip_accessor].minValues = {0, 0, 1};
  model.accessors[strip_accessor].maxValues = {1, 1, 1};

  tinygltf::Mesh two;
  two.name = "two";
  two.primitives = {primitive(tri_positions, tri_index_accessor, TINYGLTF_MODE_TRIANGLES),
                    primitive(strip_accessor, -1, TINYGLTF_MODE_TRIANGLE_STRIP)};
  tinygltf::Mesh mirrored;
  mirrored.name = "mirrored";
  mirrored.primitives = {primitive(tri_positions, -1, TINYGLTF_MODE_TRIANGLES)};
  model.meshes = {two, mirrored};

  tinygltf::Node root;
  root.mesh = 0;
  root.translation = {1, 2, 3};
  root.scale = {2, 2, 2};
  root.children = {1};
  tinygltf::Node child;
  child.mesh = 1;
  child.scale = {-1, 1, 1};
  model.nodes = {root, child};
  tinygltf::Scene scene;
  scene.nodes = {0};
  model.scenes = {scene};
  model.defaultScene = 0;
  return model;
}

void write_model(const tinygltf::Model& model, const fs::path& path) {
  tinygltf::TinyGLTF writer;
  const bool binary = path.extension() == ".glb";
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&model, path.string(), true, true, !binary, binary));
}

TEST_F(MeshIoTest, GltfMergesPrimitivesAndAppliesTransforms) {
  for (const std::string file : {"scene.gltf", "scene.glb"}) {
    SCOPED_TRACE(file);
    write_model(two_primitive_model(), path(file));
    const TriMesh mesh = read_mesh(path(file));
    // 3 + 4 vertices of mesh "two", 3 of mesh "mirrored".
    ASSERT_EQ(mesh.vertex_count(), 10u);
    ASSERT_EQ(mesh.face_count(), 4u);
    // world = T(1,2,3) * S(2): (x,y,z) -> (2x+1, 2y+2, 2z+3)
    EXPECT_EQ(mesh.positions[1], Vec3(3, 2, 3));
    EXPECT_EQ(mesh.positions[3], Vec3(1, 2, 5));
    EXPECT_EQ(mesh.positions[6], Vec3(3, 4, 5));
    // child: root * S(-1,1,1): (x,y,z) -> (-2x+1, 2y+2, 2z+3)
    EXPECT_EQ(mesh.positions[8], Vec3(-1, 2, 3));
    const std::vector<Triangle> expected = {
        {0, 1, 2},  // triangles
        {3, 4, 5},  // strip, even triangle
        {4, 6, 5},  // strip, odd triangle: reversed to keep the winding
        {7, 9, 8},  // mirrored: winding flipped
    };
    EXPECT_EQ(mesh.faces, expected);
  }
}

TEST_F(MeshIoTest, GltfWithoutScenesUsesRootNodes) {
  tinygltf::Model model = two_primitive_model();
  model.scenes.clear();
  model.defaultScene = -1;
  write_model(model, path("noscene.glb"));
  EXPECT_EQ(read_mesh(path("noscene.glb")).face_count(), 4u);
}

TEST_F(MeshIoTest, GltfLinesAreRejected) {
  tinygltf::Model model = two_primitive_model();
  model.meshes[1].name = "wire";
  model.meshes[1].primitives[0].mode = TINYGLTF_MODE_LINE;
  write_model(model, path("lines.glb"));
  try {
    read_mesh(path("lines.glb"));
    FAIL() << "expected MeshIoError";
  } catch (const MeshIoError& e) {
    EXPECT_NE(std::string(e.what()).find("primitive 0 of mesh 'wire' uses mode LINES"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("lines.glb"), std::string::npos) << e.what();
  }
}

TEST_F(MeshIoTest, GltfWithoutPositionIsRejected) {
  tinygltf::Model model = two_primitive_model();
  model.meshes[0].primitives[1].attributes = {{"NORMAL", 0}};
  write_model(model, path("nopos.gltf"));
  try {
    read_mesh(path("nopos.gltf"));
    FAIL() << "expected MeshIoError";
  } catch (const MeshIoError& e) {
    EXPECT_NE(std::string(e.what()).find("primitive 1 of mesh 'two' has no POSITION"), std::string::npos) << e.what();
  }
}

// Malformed accessors must be reported, not read out of bounds.
TEST_F(MeshIoTest, GltfBadAccessorsAreRejected) {
  auto expect_error = [this](tinygltf::Model model, const std::string& expected) {
    SCOPED_TRACE(expected);
    write_model(model, path("bad.glb"));
    try {
      read_mesh(path("bad.glb"));
      FAIL() << "expected MeshIoError";
    } catch (const MeshIoError& e) {
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  };
  tinygltf::Model model = two_primitive_model();
  model.accessors[0].count = 1000;
  expect_error(model, "reads past the end of its bufferView");
  model = two_primitive_model();
  model.bufferViews[0].byteLength = 1 << 20;
  expect_error(model, "exceeds its buffer");
  model = two_primitive_model();
  model.accessors[2].byteOffset = 20;  // strip: 20 + 3 * 24 + 12 > 96
  expect_error(model, "reads past the end of its bufferView");
  model = two_primitive_model();
  model.accessors[0].componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
  expect_error(model, "POSITION must be float VEC3");
  model = two_primitive_model();
  const std::uint16_t big[] = {0, 1, 7};
  std::memcpy(model.buffers[0].data.data() + model.bufferViews[1].byteOffset, big, sizeof big);
  expect_error(model, "index 7 is out of range (3 vertices)");
  model = two_primitive_model();
  model.nodes[1].children = {0};
  expect_error(model, "occurs twice in the node hierarchy");
  model = two_primitive_model();
  model.accessors[1].sparse.isSparse = true;
  model.accessors[1].sparse.count = 1;
  model.accessors[1].sparse.indices = {0, 1, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT};
  model.accessors[1].sparse.values = {1, 0};
  expect_error(model, "sparse accessors are not supported");
}

// A glTF from memory must not be able to pull in files from disk.
TEST_F(MeshIoTest, GltfFromMemoryRefusesExternalFiles) {
  tinygltf::Model model = two_primitive_model();
  model.buffers[0].uri = "scene.bin";
  tinygltf::TinyGLTF writer;
  ASSERT_TRUE(writer.WriteGltfSceneToFile(&model, path("ext.gltf").string(), false, false, true, false));
  ASSERT_TRUE(fs::exists(path("scene.bin")));
  EXPECT_EQ(read_mesh(path("ext.gltf")).face_count(), 4u);  // from a file: resolved next to it
  EXPECT_THROW(read_mesh_from_memory(read_bytes(path("ext.gltf")), "gltf"), MeshIoError);
  // Embedded (data URI) buffers need no file.
  write_model(two_primitive_model(), path("embedded.gltf"));
  EXPECT_EQ(read_mesh_from_memory(read_bytes(path("embedded.gltf")), "gltf").face_count(), 4u);
}

// A GLB of one JSON chunk (padded with spaces, as the format asks) and no binary chunk.
std::string glb_of_json(std::string json) {
  while (json.size() % 4 != 0) json += ' ';
  auto u32 = [](std::uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  return "glTF" + u32(2) + u32(static_cast<std::uint32_t>(20 + json.size())) + u32(static_cast<std::uint32_t>(json.size())) +
         "JSON" + json;
}

// tinygltf converts JSON to its values recursively: deep nesting (30 KB of
// brackets in `extras`) overflowed the stack of the thread reading it. The
// depth is bounded before tinygltf sees the text: exactly kMaxJsonNesting
// levels read, one more is refused, and 200,000 are refused, not a crash.
TEST_F(MeshIoTest, GltfNestingIsBoundedBeforeParsing) {
  write_model(two_primitive_model(), path("embedded.gltf"));
  const std::string json = read_bytes(path("embedded.gltf"));
  ASSERT_EQ(json.front(), '{');
  // The top-level object is one level; `extras` adds `levels` arrays.
  auto nested = [&](std::size_t levels) {
    return "{\"extras\":" + std::string(levels, '[') + std::string(levels, ']') + "," + json.substr(1);
  };
  EXPECT_EQ(read_mesh_from_memory(nested(kMaxJsonNesting - 1), "gltf").face_count(), 4u);
  EXPECT_EQ(read_mesh_from_memory(glb_of_json(nested(kMaxJsonNesting - 1)), "glb").face_count(), 4u);
  for (const std::size_t levels : {kMaxJsonNesting, std::size_t{200000}}) {
    for (const char* format : {"gltf", "glb"}) {
      const std::string text = nested(levels);
      try {
        read_mesh_from_memory(format == std::string("glb") ? glb_of_json(text) : text, format);
        ADD_FAILURE() << format << " nested " << levels << " deep was read";
      } catch (const MeshIoError& e) {
        EXPECT_NE(std::string(e.what()).find("nests deeper than 128 levels"), std::string::npos) << e.what();
      }
    }
  }
}

TEST(JsonNesting, CountsBracketsOutsideStringsOnly) {
  EXPECT_EQ(json_nesting("{}", 10), 1u);
  EXPECT_EQ(json_nesting("[[{}],[]]", 10), 3u);
  EXPECT_EQ(json_nesting(R"({"a":"[[[[","b":"\"[[[["})", 10), 1u);  // brackets in strings, an escaped quote
  EXPECT_EQ(json_nesting(R"({"a":"\\",[[]]})", 10), 3u);            // an escaped backslash ends before the quote
  EXPECT_EQ(json_nesting("]]]][[", 10), 2u);                         // stray closers never go below zero
  EXPECT_EQ(json_nesting("[[[[", 3), 4u);                            // past the bound: bound + 1
  EXPECT_EQ(json_nesting("[[[]]]", 3), 3u);                          // at the bound: its depth
}

// --- malformed files ----------------------------------------------------------

void expect_io_error(const fs::path& file, const std::string& expected_fragment = "") {
  try {
    const TriMesh mesh = read_mesh(file);
    ADD_FAILURE() << file << " was read: " << mesh.vertex_count() << " vertices, " << mesh.face_count() << " faces";
  } catch (const MeshIoError& e) {
    EXPECT_NE(std::string(e.what()).find(file.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(expected_fragment), std::string::npos) << e.what();
  }
}

TEST_F(MeshIoTest, TruncatedAndGarbageFilesAreErrors) {
  const std::string garbage = std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16) + "this is not a mesh\n";
  for (const std::string ext : {"obj", "off", "ply", "gltf", "glb"}) {
    write_bytes(path("garbage." + ext), garbage);
    expect_io_error(path("garbage." + ext));
    write_bytes(path("empty." + ext), "");
    if (ext != "obj") expect_io_error(path("empty." + ext));  // an empty OBJ is a valid empty mesh
  }

  write_bytes(path("t1.obj"), "v 0 0 0\nv 1 0 0\nv 0 1");
  expect_io_error(path("t1.obj"), "line 3: vertex needs 3 coordinates");
  write_bytes(path("t2.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2");
  expect_io_error(path("t2.obj"), "line 4: face needs at least 3 vertices");
  write_bytes(path("t3.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n");
  expect_io_error(path("t3.obj"), "vertex reference 0 is invalid");
  write_bytes(path("t4.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n");
  expect_io_error(path("t4.obj"), "points before the first vertex");

  const std::string head = read_bytes(kDataDir / "head_open.off");
  write_bytes(path("half.off"), head.substr(0, head.rfind('\n', head.size() / 2) + 1));  // whole lines
  expect_io_error(path("half.off"), "file ends after");
  write_bytes(path("cut.off"), head.substr(0, head.size() - 6));  // "3 1459 1113 1145\n" -> "3 1459 1113"
  expect_io_error(path("cut.off"), "face lists fewer than 3 vertex indices");
  write_bytes(path("neg.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -2\n");
  expect_io_error(path("neg.off"), "invalid vertex index '-2'");

  const TriMesh mesh = awkward_mesh();
  for (const std::string ext : {"ply", "glb"}) {
    write_mesh(mesh, path("whole." + ext));
    const std::string whole = read_bytes(path("whole." + ext));
    write_bytes(path("cut." + ext), whole.substr(0, whole.size() - 5));
    expect_io_error(path("cut." + ext));
    write_bytes(path("half." + ext), whole.substr(0, whole.size() / 2));
    expect_io_error(path("half." + ext));
  }
  write_bytes(path("noend.ply"), "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
  expect_io_error(path("noend.ply"), "no end_header");

  write_model(two_primitive_model(), path("whole.gltf"));
  const std::string json = read_bytes(path("whole.gltf"));
  write_bytes(path("cut.gltf"), json.substr(0, json.size() / 2));
  expect_io_error(path("cut.gltf"), "invalid glTF");
}

// Every prefix and every single-byte corruption of a small file either parses
// or throws MeshIoError: no crash, no other exception.
TEST_F(MeshIoTest, EveryPrefixAndCorruptionIsHandled) {
  const TriMesh mesh = awkward_mesh();
  for (const std::string ext : {"obj", "ply", "glb"}) {
    SCOPED_TRACE(ext);
    write_mesh(mesh, path("m." + ext));
    const std::string whole = read_bytes(path("m." + ext));
    for (std::size_t length = 0; length < whole.size(); ++length) {
      try {
        read_mesh_from_memory(whole.substr(0, length), ext);
      } catch (const MeshIoError&) {
      }
    }
    for (std::size_t at = 0; at < whole.size(); ++at) {
      for (const char value : {'\0', '\xff', '9'}) {
        std::string corrupt = whole;
        corrupt[at] = value;
        try {
          read_mesh_from_memory(corrupt, ext);
        } catch (const MeshIoError&) {
        }
      }
    }
  }
}

TEST_F(MeshIoTest, UnsupportedAndMissingFiles) {
  try {
    read_mesh(path("mesh.stl"));
    FAIL() << "expected MeshIoError";
  } catch (const MeshIoError& e) {
    EXPECT_NE(std::string(e.what()).find("unsupported format '.stl'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(".obj, .ply, .off, .gltf, .glb"), std::string::npos) << e.what();
  }
  EXPECT_THROW(read_mesh_from_memory("solid x", "stl"), MeshIoError);
  EXPECT_THROW(write_mesh(awkward_mesh(), path("mesh.off")), MeshIoError);
  expect_io_error(path("missing.obj"), "cannot open");
  fs::create_directories(path("dir.obj"));
  expect_io_error(path("dir.obj"), "is a directory");
  EXPECT_THROW(write_mesh(awkward_mesh(), path("no/such/dir/mesh.obj")), MeshIoError);
  EXPECT_THROW(write_mesh(awkward_mesh(), path("no/such/dir/mesh.glb")), MeshIoError);
  EXPECT_THROW(write_mesh(TriMesh{}, path("empty.glb")), MeshIoError);
}

}  // namespace
}  // namespace filigree
