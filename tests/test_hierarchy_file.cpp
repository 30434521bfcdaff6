// The hierarchy file: bit-identical round trips, and every kind of damage
// turned into an error that says what is wrong.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>

#include <gtest/gtest.h>

#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "hierarchy/node_graph.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer.h"
#include "runtime/deformer_model.h"
#include "support/forged_hierarchy.h"
#include "support/test_meshes.h"
#include "util/content_hash.h"

namespace filigree {
namespace {

using test::rehashed;

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

// Same bytes, element by element (float fields compared as bits, not values).
template <class T>
void expect_same_bytes(std::span<const T> a, std::span<const T> b, const char* what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(T)), 0) << what;
}

void expect_same_hierarchy(const Hierarchy& a, const Hierarchy& b) {
  expect_same_bytes<Vec3>(a.rest_positions, b.rest_positions, "rest_positions");
  expect_same_bytes<Triangle>(a.original_faces, b.original_faces, "original_faces");
  expect_same_bytes<RingCorners>(a.created_corners, b.created_corners, "created_corners");
  expect_same_bytes<Index>(a.node_vertex, b.node_vertex, "node_vertex");
  expect_same_bytes<std::uint8_t>(a.node_closed, b.node_closed, "node_closed");
  expect_same_bytes<Index>(a.ring_offsets, b.ring_offsets, "ring_offsets");
  expect_same_bytes<Index>(a.ring_vertices, b.ring_vertices, "ring_vertices");
  expect_same_bytes<std::uint16_t>(a.ring_weights, b.ring_weights, "ring_weights");
  expect_same_bytes<Vec3f>(a.node_offset, b.node_offset, "node_offset");
  expect_same_bytes<Index>(a.base_vertices, b.base_vertices, "base_vertices");
  expect_same_bytes<FaceId>(a.base_faces, b.base_faces, "base_faces");
  expect_same_bytes<Index>(a.maps_face, b.maps_face, "maps_face");
  expect_same_bytes<Barycentric16>(a.maps_bary, b.maps_bary, "maps_bary");
  EXPECT_EQ(a.mesh_hash, b.mesh_hash);
  EXPECT_EQ(a.build.requested_base_vertices, b.build.requested_base_vertices);
}

// Byte offset of section `tag`'s first element.
std::size_t section_data(const std::string& bytes, std::uint32_t tag) {
  std::size_t pos = 64;
  while (pos + 16 <= bytes.size()) {
    std::uint32_t head[2];
    std::uint64_t count;
    std::memcpy(head, bytes.data() + pos, 8);
    std::memcpy(&count, bytes.data() + pos + 8, 8);
    if (head[0] == tag) return pos + 16;
    const std::size_t size = head[1] * count;
    pos += 16 + size + (8 - size % 8) % 8;
  }
  ADD_FAILURE() << "no section " << tag;
  return 0;
}

TEST_F(HierarchyFileTest, MemoryRoundTripIsBitIdentical) {
  const Hierarchy back = deserialize_hierarchy(*bytes_);
  EXPECT_EQ(serialize_hierarchy(back), *bytes_);
  expect_same_hierarchy(back, *hierarchy_);
  // The preprocessed hierarchy filled its derived arrays itself; the loaded
  // one derived them: they agree, and both pass the full check.
  EXPECT_NO_THROW(validate_hierarchy(back));
}

TEST_F(HierarchyFileTest, LargeHierarchiesLoadOnTwoThreadsBitIdentical) {
  // From 100k vertices a load checks on two threads (the boundary check and
  // the checksum on a helper), and copies on both; the shipped meshes are
  // smaller, so a grid of 103k vertices takes that path.
  PreprocessOptions options;
  options.base_vertices = 400;
  const Hierarchy h = preprocess(test::wavy_grid(320), options);
  ASSERT_GE(h.vertex_count(), 100000u);
  const std::string bytes = serialize_hierarchy(h);
  const Hierarchy back = deserialize_hierarchy(bytes);
  expect_same_hierarchy(back, h);
  EXPECT_EQ(serialize_hierarchy(back), bytes);
  // From a file, in place.
  const auto path = temp_file("large.fgh");
  save_hierarchy(h, path);
  const Hierarchy mapped = load_hierarchy(path);
  std::filesystem::remove(path);
  EXPECT_TRUE(mapped.rest_positions.viewing());
  expect_same_hierarchy(mapped, h);
  // A forged node on that path is still refused, with what is wrong: from
  // either thread's checks.
  Hierarchy forged = h;
  forged.node_vertex.edit()[5] = forged.node_vertex[2];
  std::string msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("node 5 removes vertex"), std::string::npos) << msg;
  // Open and closed swapped between the grid's first boundary node and the
  // inner node after it (so the face count still adds up).
  forged = h;
  NodeId open = 0;
  while (open < forged.node_count() && forged.node_closed[open] != 0) ++open;
  NodeId closed = open;
  while (closed < forged.node_count() && forged.node_closed[closed] == 0) ++closed;
  ASSERT_LT(closed, forged.node_count());
  forged.node_closed.edit()[open] = 1, forged.node_closed.edit()[closed] = 0;
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("node " + std::to_string(open) + " says its ring is closed, but its vertex is on the mesh's boundary"), std::string::npos) << msg;
}

TEST_F(HierarchyFileTest, ALoadedHierarchyReadsItsFileInPlaceAndOutlivesItsName) {
  const auto path = temp_file("in_place.fgh");
  save_hierarchy(*hierarchy_, path);
  Hierarchy h = load_hierarchy(path);
  // Every stored array is a view of the mapping: nothing copied.
  EXPECT_TRUE(h.rest_positions.viewing() && h.original_faces.viewing() && h.created_corners.viewing() && h.node_vertex.viewing() &&
              h.node_closed.viewing() && h.ring_offsets.viewing() && h.ring_vertices.viewing() && h.ring_weights.viewing() &&
              h.node_offset.viewing() && h.maps_face.viewing() && h.maps_bary.viewing());
  EXPECT_EQ(h.memory_bytes(), deserialize_hierarchy(*bytes_).memory_bytes());
  // Replaced by a rename, as writers do: the loaded hierarchy still reads
  // what it loaded; then deleted: still so.
  Hierarchy other = *hierarchy_;
  other.mesh_hash ^= 1;
  save_hierarchy(other, path);
  EXPECT_EQ(serialize_hierarchy(h), *bytes_);
  std::filesystem::remove(path);
  EXPECT_EQ(serialize_hierarchy(h), *bytes_);
  // Writing to a loaded array copies it; the other views are untouched.
  const Hierarchy before = h;
  h.ring_weights.edit()[0] = static_cast<std::uint16_t>(h.ring_weights[0] + 1);
  EXPECT_FALSE(h.ring_weights.viewing());
  EXPECT_TRUE(before.ring_weights.viewing());
  EXPECT_EQ(serialize_hierarchy(before), *bytes_);
}

TEST_F(HierarchyFileTest, FloatAndFixedPointFieldsRoundTripBitExact) {
  // float32 and 16-bit fields: stored as they are in memory, no conversion on the way.
  Hierarchy h = *hierarchy_;
  h.ring_weights.edit()[0] = static_cast<std::uint16_t>(h.ring_weights[0] + 1);
  h.node_offset.edit()[1].x() = std::nextafter(h.node_offset[1].x(), 0.0f);
  h.node_offset.edit()[2].z() = 0x1p-140f;  // subnormal
  h.maps_bary.edit()[3] = {16384, 32769};
  const Hierarchy back = deserialize_hierarchy(serialize_hierarchy(h));
  expect_same_hierarchy(back, h);
}

TEST_F(HierarchyFileTest, MemoryBytesIsTheSumOfTheArrays) {
  // A loaded hierarchy allocates exactly; count by hand what each array holds.
  const Hierarchy h = deserialize_hierarchy(*bytes_);
  const std::size_t n = h.vertex_count(), nodes = h.node_count(), original = h.original_face_count();
  const std::size_t slots = h.ring_vertices.size(), created = h.created_corners.size();
  const std::size_t expected = n * (24 + 4 + 4)                    // rest_positions, maps_face, maps_bary
                               + original * 12 + created * 3       // original_faces, created_corners
                               + nodes * (4 + 1 + 12)              // node_vertex, node_closed, node_offset
                               + (nodes + 1) * 4                   // ring offsets
                               + slots * (4 + 2)                   // ring_vertices, ring_weights
                               + (h.base_vertices.size() + h.base_faces.size()) * 4;
  EXPECT_EQ(h.memory_bytes(), expected);
  EXPECT_EQ(created, slots - 2 * nodes);  // each ring of r vertices made r − 2 faces
  // A copy may hold more (capacity), never less.
  Hierarchy grown = h;
  grown.rest_positions.reserve(2 * n);
  EXPECT_EQ(grown.memory_bytes(), expected + n * 24);
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
  EXPECT_NE(error_of(b).find("unsupported format version " + std::to_string(future)), std::string::npos) << error_of(b);

  EXPECT_NE(error_of(*bytes_ + "junk").find("unexpected bytes"), std::string::npos);
}

TEST_F(HierarchyFileTest, VersionOneFilesAreRefusedWithWhatToDo) {
  // A format-1 file (before the compact layout): the header says so, and the
  // message says how to get a current file.
  std::string b = *bytes_;
  const std::uint32_t v1 = 1;
  std::memcpy(b.data() + 8, &v1, 4);
  const std::string msg = error_of(b);
  EXPECT_NE(msg.find("test.fgh: unsupported format version 1"), std::string::npos) << msg;
  EXPECT_NE(msg.find("rebuild it"), std::string::npos) << msg;
  EXPECT_NE(msg.find("filigree preprocess"), std::string::npos) << msg;

  const auto path = temp_file("v1.fgh");
  std::ofstream(path, std::ios::binary).write(b.data(), static_cast<std::streamsize>(b.size()));
  for (const auto& attempt : {std::function<void()>([&] { load_hierarchy(path); }), std::function<void()>([&] { read_hierarchy_file_info(path); })}) {
    try {
      attempt();
      ADD_FAILURE() << "a version 1 file was accepted";
    } catch (const HierarchyFileError& e) {
      EXPECT_NE(std::string(e.what()).find("format version 1"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  }
  std::filesystem::remove(path);
}

// A hierarchy written as version 2 did (float32 weights and barycentrics,
// the deleted faces and child lists stored): the old writer, kept here.
std::string serialize_v2(const Hierarchy& h) {
  const NodeGraph g(h);
  std::vector<float> weights;
  for (NodeId k = 0; k < h.node_count(); ++k) {
    double sum = 0.0;
    for (std::uint16_t w : h.weights(k)) sum += w;
    for (std::uint16_t w : h.weights(k)) weights.push_back(static_cast<float>(w / sum));
  }
  std::vector<FaceId> removed(h.ring_vertices.size(), kNone);
  std::vector<Index> child_offsets{0};
  std::vector<NodeId> children;
  for (NodeId k = 0; k < h.node_count(); ++k) {
    std::copy(g.removed_faces_of(k).begin(), g.removed_faces_of(k).end(), removed.begin() + h.ring_offsets[k]);
    children.insert(children.end(), g.children_of(k).begin(), g.children_of(k).end());
    child_offsets.push_back(static_cast<Index>(children.size()));
  }
  std::vector<Vec3f> bary;
  for (Index v = 0; v < h.vertex_count(); ++v) bary.push_back(h.maps_barycentric(v).cast<float>());
  std::string payload;
  auto section = [&](std::uint32_t tag, const auto& v) {
    const std::uint32_t head[2] = {tag, static_cast<std::uint32_t>(sizeof(v[0]))};
    const std::uint64_t count = v.size();
    payload.append(reinterpret_cast<const char*>(head), 8);
    payload.append(reinterpret_cast<const char*>(&count), 8);
    payload.append(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(v[0]));
    payload.append((8 - v.size() * sizeof(v[0]) % 8) % 8, '\0');
  };
  section(1, h.rest_positions), section(2, h.original_faces), section(3, h.created_corners), section(4, h.node_vertex);
  section(5, h.node_closed), section(6, h.ring_offsets), section(7, h.ring_vertices), section(8, weights);
  // Offsets as zeros: the loader recomputes them for the 16-bit weights, so
  // only that recomputation can give them back.
  section(9, std::vector<Vec3f>(h.node_offset.size(), Vec3f::Zero())), section(10, removed), section(11, child_offsets), section(12, children);
  section(13, h.maps_face), section(14, bary);
  struct Build {
    std::uint64_t requested;
    double seconds;
    std::uint32_t threads, reserved;
  };
  section(15, std::vector<Build>{{h.build.requested_base_vertices, h.build.build_seconds, h.build.threads, 0}});
  std::string out = serialize_hierarchy(h).substr(0, 64);  // the header: magic, sizes, counts; then patched
  const std::uint32_t version = 2, sections = 15;
  const std::uint64_t size = payload.size();
  std::memcpy(out.data() + 8, &version, 4);
  std::memcpy(out.data() + 24, &size, 8);
  std::memcpy(out.data() + 56, &sections, 4);
  return rehashed(out + payload);
}

// A version 2 file (what a session persisted by the previous server names)
// still loads, into the same hierarchy up to the 16-bit rounding of its
// float weights (its offsets redone for them), and deforms like it within
// 1e-5 of the diagonal.
TEST_F(HierarchyFileTest, VersionTwoFilesLoadAndDeformAsBefore) {
  const Hierarchy& h = *hierarchy_;
  const Hierarchy old = deserialize_hierarchy(serialize_v2(h), "v2.fgh");
  EXPECT_NO_THROW(validate_hierarchy(old));
  EXPECT_EQ(old.rest_positions, h.rest_positions);
  EXPECT_EQ(old.ring_vertices, h.ring_vertices);
  EXPECT_EQ(old.created_corners, h.created_corners);
  EXPECT_EQ(old.base_faces, h.base_faces);
  EXPECT_EQ(old.maps_bary, h.maps_bary);
  EXPECT_EQ(old.mesh_hash, h.mesh_hash);
  for (std::size_t j = 0; j < h.ring_weights.size(); ++j) ASSERT_NEAR(old.ring_weights[j], h.ring_weights[j], 8) << j;
  // The file's offsets were zeros: these are the loader's, redone for the
  // 16-bit weights (1.7e-5 apart here, from the weights' rounding).
  double offset_gap = 0.0, offset_size = 0.0;
  for (NodeId k = 0; k < h.node_count(); ++k) {
    offset_gap = std::max(offset_gap, double((old.node_offset[k] - h.node_offset[k]).norm()));
    offset_size = std::max(offset_size, double(h.node_offset[k].norm()));
  }
  EXPECT_LT(offset_gap, 1e-3 * offset_size);
  EXPECT_NO_THROW(NodeGraph{old});

  const double diag = bounding_box_diagonal(h.rest_positions);
  Pose rest, bent;
  for (Index v : h.base_vertices) {
    rest.positions.push_back(h.rest_positions[v]);
    bent.positions.push_back(h.rest_positions[v] + Vec3(0.0, 0.2 * h.rest_positions[v].x(), 0.0));  // a shear
  }
  Deformer now(h), before(old);
  const std::vector<Vec3> a = now.deform(bent).positions, b = before.deform(bent).positions;
  double worst = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) worst = std::max(worst, (a[i] - b[i]).norm());
  EXPECT_LT(worst, 1e-5 * diag);
  const std::vector<Vec3> back = before.deform(rest).positions;  // its offsets were redone for its weights
  for (std::size_t i = 0; i < back.size(); ++i) ASSERT_LT((back[i] - h.rest_positions[i]).norm(), 1e-9 * diag) << i;
}

TEST_F(HierarchyFileTest, TruncatedOrCorruptFilesOnDiskAreErrorsNotCrashes) {
  // load_hierarchy maps the file: every size is checked against the mapping
  // before anything is read through it.
  const auto path = temp_file("damaged.fgh");
  for (std::size_t size : {std::size_t{0}, std::size_t{63}, std::size_t{64}, std::size_t{4096}, bytes_->size() / 3,
                           bytes_->size() - 8, bytes_->size() - 1}) {
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(bytes_->data(), static_cast<std::streamsize>(size));
    try {
      load_hierarchy(path);
      ADD_FAILURE() << "size " << size << " accepted";
    } catch (const HierarchyFileError& e) {
      EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << "size " << size << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  }
  // The whole file, then cut short in place (as a crashed copy would leave it).
  save_hierarchy(*hierarchy_, path);
  std::filesystem::resize_file(path, bytes_->size() - 100);
  EXPECT_THROW(load_hierarchy(path), HierarchyFileError);
  for (std::size_t at : {std::size_t{100}, bytes_->size() / 2, bytes_->size() - 3}) {
    std::string b = *bytes_;
    b[at] = static_cast<char>(b[at] ^ 0x01);
    std::ofstream(path, std::ios::binary | std::ios::trunc).write(b.data(), static_cast<std::streamsize>(b.size()));
    try {
      load_hierarchy(path);
      ADD_FAILURE() << "flipped byte " << at << " accepted";
    } catch (const HierarchyFileError& e) {
      EXPECT_NE(std::string(e.what()).find("corrupt"), std::string::npos) << e.what();
    }
  }
  // A directory is not a hierarchy file.
  EXPECT_THROW(load_hierarchy(path.parent_path()), HierarchyFileError);
  std::filesystem::remove(path);
}

TEST_F(HierarchyFileTest, UnalignedBuffersLoadToo) {
  // Sections are read in place; a buffer that is not 8-byte aligned is copied first.
  std::string shifted = " " + *bytes_;
  const Hierarchy back = deserialize_hierarchy(std::span<const char>(shifted).subspan(1));
  expect_same_hierarchy(back, *hierarchy_);
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
  const NodeId last = static_cast<NodeId>(forged.node_count() - 1);
  forged.ring_vertices.edit()[forged.ring_offsets[last]] = forged.node_vertex[0];  // gone before the last node
  std::string msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("corrupt: invalid hierarchy: node " + std::to_string(last) + " has ring vertex " +
                     std::to_string(forged.node_vertex[0]) + ", removed before it"),
            std::string::npos)
      << msg;

  forged = *hierarchy_;
  forged.node_vertex.edit()[5] = forged.node_vertex[2];
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("node 5 removes vertex"), std::string::npos) << msg;

  forged = *hierarchy_;
  forged.original_faces.edit()[3][1] = static_cast<Index>(forged.vertex_count());
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("face 3"), std::string::npos) << msg;

  forged = *hierarchy_;
  forged.maps_bary.edit()[7] = {40000, 40000};
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("barycentric"), std::string::npos) << msg;

  // A removed vertex mapped into the first face past the base mesh's last:
  // it would read past the end of the base faces. The last valid face loads.
  const std::size_t base_faces = hierarchy_->base_faces.size();
  const Index removed = hierarchy_->node_vertex[0];
  forged = *hierarchy_;
  forged.maps_face.edit()[removed] = static_cast<Index>(base_faces);
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("vertex " + std::to_string(removed) + " is parameterised in a face outside the base mesh"),
            std::string::npos)
      << msg;
  forged.maps_face.edit()[removed] = static_cast<Index>(base_faces - 1);
  EXPECT_NO_THROW(deserialize_hierarchy(serialize_hierarchy(forged), "forged"));

  forged = *hierarchy_;
  forged.ring_weights.edit()[2] = 0;
  EXPECT_NE(error_of(serialize_hierarchy(forged)).find("zero ring weight"), std::string::npos);

  // Open and closed rings swapped between a boundary node and an inner one:
  // the face count still adds up, the boundary does not.
  forged = *hierarchy_;
  const auto first_with = [&](std::uint8_t closed) {
    NodeId k = 0;
    while (k < forged.node_count() && forged.node_closed[k] != closed) ++k;
    return k;
  };
  const NodeId open = first_with(0), closed = first_with(1);
  ASSERT_LT(open, forged.node_count());  // the fixture has a boundary
  forged.node_closed.edit()[open] = 1, forged.node_closed.edit()[closed] = 0;
  msg = error_of(serialize_hierarchy(forged));
  const NodeId first = std::min(open, closed);
  EXPECT_NE(msg.find("node " + std::to_string(first) + " says its ring is " + (first == open ? "closed, but its vertex is on" : "open, but its vertex is not on") +
                     " the mesh's boundary"),
            std::string::npos)
      << msg;

  // Created faces that do not triangulate their ring: one turned over, one
  // twice (and so another missing).
  const NodeId quad = [&] {
    NodeId k = 0;
    while (hierarchy_->ring_size(k) < 4) ++k;
    return k;
  }();
  const std::size_t at = hierarchy_->first_created_face(quad) - hierarchy_->original_face_count();
  forged = *hierarchy_;
  std::swap(forged.created_corners.edit()[at][1], forged.created_corners.edit()[at][2]);
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("node " + std::to_string(quad) + "'s created faces do not triangulate its ring"), std::string::npos) << msg;
  forged = *hierarchy_;
  forged.created_corners.edit()[at + 1] = forged.created_corners[at];
  msg = error_of(serialize_hierarchy(forged));
  EXPECT_NE(msg.find("do not triangulate its ring"), std::string::npos) << msg;

  // Stored forms the writer never makes, edited into the bytes.
  std::string b = *bytes_;
  b[section_data(b, 3) + 4] = 40;  // a created face's corner past its ring
  msg = error_of(rehashed(b));
  EXPECT_NE(msg.find("corners outside its ring"), std::string::npos) << msg;
}

// What loading leaves unchecked (which faces each removal deleted) is checked
// when a changing cut first needs it: a clear error, not a wrong cut.
TEST_F(HierarchyFileTest, ForgedFansFailWhenTheNodeGraphIsDerived) {
  EXPECT_NO_THROW(NodeGraph{*hierarchy_});
  const auto graph_error = [](const Hierarchy& h) -> std::string {
    try {
      NodeGraph g(h);
    } catch (const HierarchyError& e) {
      return e.what();
    }
    return "no error";
  };
  Hierarchy h = *hierarchy_;
  const NodeId k = test::flip_a_quad_diagonal(h);
  ASSERT_NE(k, kNone);
  Hierarchy loaded = deserialize_hierarchy(serialize_hierarchy(h));  // loading sees a valid triangulation
  EXPECT_NE(graph_error(loaded).find("which is not in its fan"), std::string::npos) << graph_error(loaded);

  // Through a model, the error reaches whoever first sets a finite T.
  const auto forged = std::make_shared<const Hierarchy>(std::move(loaded));
  const auto model = DeformerModel::create(forged);
  EXPECT_THROW((void)model->node_graph(), HierarchyError);
  EXPECT_THROW((void)model->node_graph(), HierarchyError);  // again: no half-built graph is handed out
  // Also when the graph is derived on a second thread, beside the Laplacian.
  const auto fresh = DeformerModel::create(forged);
  EXPECT_THROW(fresh->derive_for_cuts(), HierarchyError);
  EXPECT_TRUE(fresh->optimisation_data_derived());
  EXPECT_THROW(fresh->derive_for_cuts(), HierarchyError);
}

TEST_F(HierarchyFileTest, InMemoryValidationChecksTheDerivedArrays) {
  // Arrays a file never stores must still agree with what they derive from
  // in a hierarchy built in memory.
  EXPECT_NO_THROW(validate_hierarchy(*hierarchy_));
  const auto message = [](const Hierarchy& h) -> std::string {
    try {
      validate_hierarchy(h);
    } catch (const HierarchyError& e) {
      return e.what();
    }
    return "no error";
  };
  Hierarchy h = *hierarchy_;
  h.created_corners.edit().back() = {0, 1, 1};
  EXPECT_NE(message(h).find("corners outside its ring"), std::string::npos) << message(h);
  h = *hierarchy_;
  h.base_vertices.pop_back();
  EXPECT_NE(message(h).find("base vertex count"), std::string::npos) << message(h);
  h = *hierarchy_;
  h.base_faces.pop_back();
  EXPECT_NE(message(h).find("base faces are not"), std::string::npos) << message(h);
}

TEST_F(HierarchyFileTest, FacesAreTheTrianglesTheRemovalsMadeAndUnmade) {
  const Hierarchy& h = *hierarchy_;
  // Every face in id order, as for_each_face visits them and face() finds them.
  std::vector<Triangle> all;
  h.for_each_face([&](FaceId f, const Triangle& t) {
    ASSERT_EQ(f, all.size());
    all.push_back(t);
  });
  ASSERT_EQ(all.size(), h.face_count());
  ASSERT_GT(all.size(), h.original_face_count());
  for (FaceId f = 0; f < all.size(); ++f) ASSERT_EQ(h.face(f), all[f]) << "face " << f;
  std::size_t checked = 0;
  const NodeGraph graph(h);
  for (NodeId k = 0; k < h.node_count(); ++k) {
    const auto ring = h.ring(k);
    // Created faces join ring vertices, and their creator is k.
    for (FaceId f : h.created_faces_of(k)) {
      ASSERT_EQ(h.creator(f), k) << "face " << f;
      for (Index c : all[f]) ASSERT_NE(std::find(ring.begin(), ring.end(), c), ring.end()) << "face " << f;
    }
    // Slot i of the fan is (v, ring[i], ring[i+1]), up to rotation, whoever made it.
    const auto removed = graph.removed_faces_of(k);
    ASSERT_EQ(removed.size(), h.fan_size(k));
    for (std::size_t i = 0; i < removed.size(); ++i) {
      const Triangle t = all[removed[i]];
      const Triangle fan = h.fan_face(k, i);
      ASSERT_EQ(fan, (Triangle{h.node_vertex[k], ring[i], ring[(i + 1) % ring.size()]}));
      const bool rotated = t == fan || t == Triangle{fan[1], fan[2], fan[0]} || t == Triangle{fan[2], fan[0], fan[1]};
      ASSERT_TRUE(rotated) << "node " << k << " slot " << i;
      checked += removed[i] >= h.original_face_count() ? 1 : 0;
    }
  }
  EXPECT_GT(checked, 0u);  // some removed faces were made by children
  EXPECT_EQ(h.creator(0), kNone);
  EXPECT_THROW((void)h.creator(static_cast<FaceId>(h.face_count())), std::out_of_range);
}

// The hierarchy's 16-bit fixed point: weights stay positive and sum to 1 up
// to a step each; barycentrics keep corners exact and b0 + b1 ≤ 1.
TEST(FixedPoint, WeightsAndBarycentrics) {
  const std::vector<double> w = {1e-9, 0.25, 0.5, 0.25 - 1e-9};
  const std::vector<std::uint16_t> q = quantize_ring_weights(w);
  EXPECT_EQ(q, (std::vector<std::uint16_t>{1, 16384, 32768, 16384}));  // the tiny weight kept, not 0
  EXPECT_EQ(quantize_ring_weights(std::vector<double>{1.0}), std::vector<std::uint16_t>{65535});
  for (const double third : {1.0 / 3.0, 0.2, 0.7}) {
    const std::vector<std::uint16_t> r = quantize_ring_weights(std::vector<double>{third, 1.0 - third});
    EXPECT_NEAR((r[0] + r[1]) / 65535.0, 1.0, 1.0 / 65535.0);
    EXPECT_NEAR(r[0] / 65535.0, third, 0.5 / 65535.0);
  }

  EXPECT_EQ(quantize_barycentric(Vec3(1, 0, 0)), (Barycentric16{65535, 0}));
  EXPECT_EQ(quantize_barycentric(Vec3(0, 1, 0)), (Barycentric16{0, 65535}));
  EXPECT_EQ(quantize_barycentric(Vec3(0, 0, 1)), (Barycentric16{0, 0}));
  EXPECT_EQ(quantize_barycentric(Vec3(-1e-12, 0.5, 0.5)), (Barycentric16{0, 32768}));  // rounding error below 0
  const Barycentric16 over = quantize_barycentric(Vec3(0.5 + 4e-6, 0.5 + 4e-6, -8e-6));  // rounds to 32768 + 32768
  EXPECT_LE(over[0] + over[1], 65535);
  Hierarchy h;
  h.maps_bary = {quantize_barycentric(Vec3(0.2, 0.3, 0.5)), over};
  for (Index i = 0; i < 2; ++i) {
    const Vec3 b = h.maps_barycentric(i);
    EXPECT_GE(b.minCoeff(), 0.0);
    EXPECT_NEAR(b.sum(), 1.0, 1e-15);
  }
  EXPECT_NEAR((h.maps_barycentric(0) - Vec3(0.2, 0.3, 0.5)).norm(), 0.0, 1.0 / 65535.0);
}

TEST_F(HierarchyFileTest, MissingFileIsAnError) {
  EXPECT_THROW(load_hierarchy(temp_file("does_not_exist.fgh")), HierarchyFileError);
}

}  // namespace
}  // namespace filigree
