// SessionInfo as JoinSession and SetOptions send it (server/session_info_wire.h):
// the slices parse to the same message as the typed one, `rest` occurs once
// on the wire, and the mesh's bytes are shared by every answer, not copied.

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>
#include <grpcpp/impl/codegen/proto_utils.h>
#include <gtest/gtest.h>

#include "server/session_info_wire.h"

namespace filigree::server {
namespace {

struct Sample {
  v1::BaseMesh base;
  v1::RestMesh rest;  // without ids
  std::vector<std::uint32_t> ids;
  v1::SessionInfo own;
};

Sample sample(std::size_t vertices, bool with_ids) {
  std::mt19937 rng(11);
  Sample s;
  for (int i = 0; i < 30; ++i) s.base.add_positions(static_cast<float>(rng() % 1000) / 7.0f);
  for (int i = 0; i < 24; ++i) s.base.add_faces(rng() % 10);
  for (std::uint32_t i = 0; i < 10; ++i) s.base.add_original_ids(i * 3);
  s.rest.set_vertex_count(static_cast<std::uint32_t>(vertices));
  for (std::size_t i = 0; i < 3 * vertices; ++i) s.rest.add_positions(static_cast<float>(rng()) / 1e6f);
  for (std::size_t i = 0; i < 6 * vertices; ++i) s.rest.add_faces(static_cast<std::uint32_t>(rng() % vertices));
  if (with_ids)
    for (std::size_t i = 0; i < vertices; ++i) s.ids.push_back(static_cast<std::uint32_t>(rng() % (4 * vertices)));
  s.own.set_session_id("s-0123456789");
  s.own.set_mesh_hash("0123456789abcdef");
  s.own.mutable_options()->set_threshold(0.25);
  s.own.set_version(300);
  s.own.mutable_skeleton()->add_joints()->set_name("hip");
  return s;
}

v1::SessionInfo typed(const Sample& s) {
  v1::SessionInfo info = s.own;
  *info.mutable_base() = s.base;
  *info.mutable_rest() = s.rest;
  info.mutable_rest()->mutable_uploaded_ids()->Add(s.ids.begin(), s.ids.end());
  return info;
}

std::string flat(const grpc::ByteBuffer& b) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(b.Dump(&slices).ok());
  std::string out;
  for (const grpc::Slice& s : slices) out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return out;
}

// How often top-level field `number` occurs in `bytes`.
int occurrences(const std::string& bytes, int number) {
  google::protobuf::io::CodedInputStream in(reinterpret_cast<const std::uint8_t*>(bytes.data()), static_cast<int>(bytes.size()));
  int n = 0;
  for (std::uint32_t tag; (tag = in.ReadTag()) != 0;) {
    n += google::protobuf::internal::WireFormatLite::GetTagFieldNumber(tag) == number;
    EXPECT_TRUE(google::protobuf::internal::WireFormatLite::SkipField(&in, tag));
  }
  return n;
}

TEST(SessionInfoWire, ParsesAsTheTypedMessage) {
  for (const bool with_ids : {true, false}) {
    const Sample s = sample(5000, with_ids);
    const MeshWire mesh(s.base, s.rest);
    const grpc::ByteBuffer wire = session_info_wire(s.own, mesh, uploaded_ids_field(s.ids), SIZE_MAX);
    v1::SessionInfo parsed;
    grpc::ByteBuffer copy(wire);
    ASSERT_TRUE(grpc::SerializationTraits<v1::SessionInfo>::Deserialize(&copy, &parsed).ok()) << with_ids;
    EXPECT_EQ(parsed.SerializeAsString(), typed(s).SerializeAsString()) << "with ids: " << with_ids;
    // One occurrence of each field: a parser that replaces a repeated message field (JavaScript's) reads the same.
    const std::string bytes = flat(wire);
    EXPECT_EQ(occurrences(bytes, 4), 1) << "rest";
    EXPECT_EQ(occurrences(bytes, 3), 1) << "base";
    EXPECT_EQ(bytes.size(), typed(s).ByteSizeLong());
  }
}

TEST(SessionInfoWire, AnEmptyMeshStillHasItsFields) {
  const Sample s = sample(0, false);
  const MeshWire mesh(v1::BaseMesh{}, s.rest);
  v1::SessionInfo parsed;
  grpc::ByteBuffer wire = session_info_wire(s.own, mesh, uploaded_ids_field({}), SIZE_MAX);
  ASSERT_TRUE(grpc::SerializationTraits<v1::SessionInfo>::Deserialize(&wire, &parsed).ok());
  EXPECT_TRUE(parsed.has_base());
  EXPECT_TRUE(parsed.has_rest());
  EXPECT_EQ(parsed.session_id(), s.own.session_id());
}

TEST(SessionInfoWire, AnswersShareTheMeshBytes) {
  const Sample s = sample(20000, true);
  const MeshWire mesh(s.base, s.rest);
  const grpc::Slice ids = uploaded_ids_field(s.ids);
  std::vector<grpc::Slice> a, b;
  ASSERT_TRUE(session_info_wire(s.own, mesh, ids, SIZE_MAX).Dump(&a).ok());
  v1::SessionInfo other = s.own;
  other.set_version(301);
  ASSERT_TRUE(session_info_wire(other, mesh, ids, SIZE_MAX).Dump(&b).ok());
  ASSERT_EQ(a.size(), 4u);
  ASSERT_EQ(b.size(), 4u);
  for (std::size_t i = 1; i < 4; ++i) EXPECT_EQ(a[i].begin(), b[i].begin()) << "slice " << i << " was copied";
  EXPECT_EQ(a[1].begin(), mesh.rest_body().begin());
  EXPECT_EQ(a[3].begin(), mesh.base_field().begin());
}

TEST(SessionInfoWire, ARestOverTheInlineLimitIsASummaryAndTheRestIsUnchanged) {
  const Sample s = sample(3000, true);
  const MeshWire mesh(s.base, s.rest);
  const grpc::Slice ids = uploaded_ids_field(s.ids);
  const std::size_t rest_bytes = mesh.rest_body().size() + ids.size();
  auto parse = [&](std::size_t most) {
    grpc::ByteBuffer wire = session_info_wire(s.own, mesh, ids, most);
    v1::SessionInfo parsed;
    EXPECT_TRUE(grpc::SerializationTraits<v1::SessionInfo>::Deserialize(&wire, &parsed).ok());
    return parsed;
  };
  // At the limit the rest goes whole; one byte under it, in parts.
  EXPECT_EQ(parse(rest_bytes).SerializeAsString(), typed(s).SerializeAsString());
  const v1::SessionInfo summary = parse(rest_bytes - 1);
  EXPECT_TRUE(summary.rest().in_parts());
  EXPECT_EQ(summary.rest().vertex_count(), s.rest.vertex_count());
  EXPECT_EQ(summary.rest().face_count(), static_cast<std::uint32_t>(s.rest.faces_size() / 3));
  EXPECT_EQ(summary.rest().positions_size() + summary.rest().faces_size() + summary.rest().uploaded_ids_size(), 0);
  // Everything else is the whole answer's.
  v1::SessionInfo expected = typed(s);
  expected.clear_rest();
  v1::SessionInfo without_rest = summary;
  without_rest.clear_rest();
  EXPECT_EQ(without_rest.SerializeAsString(), expected.SerializeAsString());
}

TEST(SessionInfoWire, RefusesMisuse) {
  Sample s = sample(10, true);
  v1::RestMesh with_ids = s.rest;
  with_ids.add_uploaded_ids(1);
  EXPECT_THROW(MeshWire(s.base, with_ids), std::invalid_argument);
  const MeshWire mesh(s.base, s.rest);
  v1::SessionInfo own = s.own;
  own.mutable_rest()->set_vertex_count(1);
  EXPECT_THROW(session_info_wire(own, mesh, grpc::Slice(), SIZE_MAX), std::invalid_argument);
}

}  // namespace
}  // namespace filigree::server
