// A frame serialized once for every stream (server/serialized_frame.h): what
// each stream sends parses to the frame (with the stream's pose id), the
// bytes are shared, not copied, and their buffer goes back to its pool only
// once nothing (neither the frame nor a stream's write) holds it.

#include <cstdint>
#include <limits>
#include <random>
#include <thread>
#include <vector>

#include <grpcpp/impl/codegen/proto_utils.h>
#include <gtest/gtest.h>

#include "server/serialized_frame.h"

namespace filigree::server {
namespace {

v1::Frame sample_frame() {
  v1::Frame f;
  f.set_version(7);
  f.set_vertex_count(40000);
  f.set_keyframe_version(5);
  f.set_max_error(1e-4f);
  f.mutable_stats()->set_compute_ms(1.5);
  std::mt19937 rng(3);
  for (std::uint32_t c = 0; c < 3; ++c) {
    v1::DeltaChunk& chunk = *f.add_chunks();
    chunk.set_first_vertex(c * 16384);
    chunk.set_vertex_count(16384);
    std::string bytes(5000 + 1000 * c, '\0');
    for (char& b : bytes) b = static_cast<char>(rng());
    chunk.set_deltas(bytes);
    for (int r = 0; r < 40; ++r) chunk.add_runs(rng() % 50);
  }
  return f;
}

v1::Frame parsed(grpc::ByteBuffer bytes) {
  v1::Frame f;
  EXPECT_TRUE(grpc::SerializationTraits<v1::Frame>::Deserialize(&bytes, &f).ok());
  return f;
}

std::vector<grpc::Slice> slices_of(const grpc::ByteBuffer& b) {
  std::vector<grpc::Slice> slices;
  EXPECT_TRUE(b.Dump(&slices).ok());
  return slices;
}

TEST(SerializedFrame, EveryStreamReadsTheFrameAndADriversCarriesItsPoseId) {
  const v1::Frame frame = sample_frame();
  const SerializedFrame wire(frame, std::make_shared<BufferPool<char>>(1));
  EXPECT_EQ(wire.size(), frame.ByteSizeLong());
  EXPECT_EQ(parsed(wire.for_stream(0)).SerializeAsString(), frame.SerializeAsString());
  for (const std::uint64_t pose_id : {std::uint64_t{1}, std::uint64_t{127}, std::uint64_t{128}, std::uint64_t{300000},
                                      std::numeric_limits<std::uint64_t>::max()}) {
    v1::Frame expected = frame;
    expected.set_pose_id(pose_id);
    EXPECT_EQ(parsed(wire.for_stream(pose_id)).SerializeAsString(), expected.SerializeAsString()) << "pose id " << pose_id;
  }
}

TEST(SerializedFrame, AClipStreamsFramesCarryTheClipTimeOfTheirSample) {
  const v1::Frame frame = sample_frame();
  const SerializedFrame wire(frame, std::make_shared<BufferPool<char>>(1));
  // Times whose bytes differ in every position, a negative one and a denormal.
  for (const double seconds : {0.25, 1.0 / 3.0, 123456.789, -2.5, 5e-324}) {
    v1::Frame expected = frame;
    expected.set_pose_id(7);
    expected.set_clip_seconds(seconds);
    EXPECT_EQ(parsed(wire.for_stream(7, seconds)).SerializeAsString(), expected.SerializeAsString()) << seconds;
    expected.clear_pose_id();
    EXPECT_EQ(parsed(wire.for_stream(0, seconds)).SerializeAsString(), expected.SerializeAsString()) << seconds;
  }
}

TEST(SerializedFrame, StreamsShareOneCopyOfTheBytes) {
  const SerializedFrame wire(sample_frame(), nullptr);
  const auto a = slices_of(wire.for_stream(0)), b = slices_of(wire.for_stream(42)), c = slices_of(wire.for_stream(43));
  ASSERT_EQ(a.size(), 1u);
  ASSERT_EQ(b.size(), 2u);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(a[0].begin(), b[0].begin()) << "a driver's frame must not copy the body";
  EXPECT_EQ(a[0].begin(), c[0].begin());
  EXPECT_EQ(a[0].size(), wire.size());
}

TEST(SerializedFrame, EmbeddedInAnAnswerItParsesAsTheTypedMessageAndIsNotCopied) {
  // GetState's answer: a head (version, pose), the frame and its keyframe.
  const v1::Frame frame = sample_frame();
  v1::Frame key = sample_frame();
  key.set_version(5);
  const SerializedFrame frame_wire(frame, nullptr), key_wire(key, nullptr), empty_wire(v1::Frame{}, nullptr);
  v1::SessionState head;
  head.set_version(7);
  for (int i = 0; i < 300; ++i) head.add_pose(0.5f * static_cast<float>(i));
  v1::SessionState expected = head;
  *expected.mutable_frame() = frame;
  *expected.mutable_keyframe() = key;
  const auto parse = [](grpc::ByteBuffer b) {
    v1::SessionState s;
    EXPECT_TRUE(grpc::SerializationTraits<v1::SessionState>::Deserialize(&b, &s).ok());
    return s;
  };
  const grpc::ByteBuffer both = message_with_frames(head.SerializeAsString(), {{3, &frame_wire}, {4, &key_wire}});
  EXPECT_EQ(parse(both).SerializeAsString(), expected.SerializeAsString());
  const auto slices = slices_of(both);
  ASSERT_EQ(slices.size(), 4u);
  EXPECT_EQ(slices[1].begin(), frame_wire.bytes().begin()) << "the frame was copied";
  EXPECT_EQ(slices[3].begin(), key_wire.bytes().begin()) << "the keyframe was copied";

  // An empty frame (the rest pose's) is still present; no frames: the head alone.
  const v1::SessionState with_empty = parse(message_with_frames(head.SerializeAsString(), {{3, &empty_wire}}));
  EXPECT_TRUE(with_empty.has_frame());
  EXPECT_FALSE(with_empty.has_keyframe());
  EXPECT_EQ(parse(message_with_frames(head.SerializeAsString(), {})).SerializeAsString(), head.SerializeAsString());
  EXPECT_EQ(parse(message_with_frames(std::string(), {})).SerializeAsString(), std::string());
}

TEST(SerializedOnce, EveryCallerGetsTheSameBytesSerializedOnce) {
  // A frame's overlays, as GetOverlays answers every poll of every viewer.
  auto overlays = std::make_shared<v1::Overlays>();
  overlays->set_ready(true);
  overlays->set_version(12);
  for (std::uint32_t i = 0; i < 50000; ++i) overlays->add_region_of(i % 7);
  overlays->set_region_count(7);
  const SerializedOnce once(overlays);
  // First callers racing: one serialization, one copy of the bytes.
  std::vector<std::vector<grpc::Slice>> seen(4);
  std::vector<std::thread> callers;
  for (auto& slices : seen) callers.emplace_back([&] { slices = slices_of(once.bytes()); });
  for (auto& t : callers) t.join();
  for (const auto& slices : seen) {
    ASSERT_EQ(slices.size(), 1u);
    EXPECT_EQ(slices[0].begin(), seen[0][0].begin()) << "serialized more than once";
  }
  grpc::ByteBuffer bytes = once.bytes();
  v1::Overlays parsed;
  ASSERT_TRUE(grpc::SerializationTraits<v1::Overlays>::Deserialize(&bytes, &parsed).ok());
  EXPECT_EQ(parsed.SerializeAsString(), overlays->SerializeAsString());
}

TEST(SerializedFrame, ItsBufferGoesBackToThePoolOnlyWhenTheLastWriteReleasesIt) {
  auto pool = std::make_shared<BufferPool<char>>(1);
  grpc::ByteBuffer in_flight;  // a stream's write that outlives the frame
  const std::uint8_t* first = nullptr;
  {
    const SerializedFrame wire(sample_frame(), pool);
    in_flight = wire.for_stream(9);
    first = slices_of(in_flight)[0].begin();
    EXPECT_EQ(pool->free_buffers(), 0u);
  }
  EXPECT_EQ(pool->free_buffers(), 0u) << "a write still holds the bytes";
  EXPECT_EQ(parsed(in_flight).pose_id(), 9u);  // and they are intact
  in_flight.Clear();
  EXPECT_EQ(pool->free_buffers(), 1u);
  // The next frame of the same size reuses the buffer: no new memory.
  const SerializedFrame next(sample_frame(), pool);
  EXPECT_EQ(pool->free_buffers(), 0u);
  EXPECT_EQ(slices_of(next.for_stream(0))[0].begin(), first);
}

TEST(SerializedFrame, AnEmptyFrameIsAnEmptyMessage) {
  const SerializedFrame wire(v1::Frame{}, nullptr);
  EXPECT_EQ(wire.size(), 0u);
  EXPECT_EQ(parsed(wire.for_stream(5)).pose_id(), 5u);
}

TEST(LazySerializedFrame, TheFirstCallerSerializesAndEveryOtherSharesIt) {
  const v1::Frame frame = sample_frame();
  const LazySerializedFrame lazy;
  auto pool = std::make_shared<BufferPool<char>>(1);
  std::vector<const SerializedFrame*> seen(4, nullptr);
  std::vector<std::thread> threads;
  for (std::size_t t = 0; t < seen.size(); ++t) threads.emplace_back([&, t] { seen[t] = &lazy.get(frame, pool); });
  for (auto& t : threads) t.join();
  for (const SerializedFrame* s : seen) EXPECT_EQ(s, seen[0]);
  // Serialized once: a later call gives the bytes a write still holds (a
  // second serialization could not reuse that buffer, and would land
  // elsewhere).
  const grpc::ByteBuffer held = lazy.get(frame, pool).for_stream(0);
  EXPECT_EQ(slices_of(held)[0].size(), frame.ByteSizeLong());
  EXPECT_EQ(slices_of(lazy.get(frame, pool).for_stream(0))[0].begin(), slices_of(held)[0].begin());
  // A copy (a frame copied to add a format) serializes on its own.
  const LazySerializedFrame copy(lazy);
  EXPECT_NE(&copy.get(frame, pool), seen[0]);
}

}  // namespace
}  // namespace filigree::server
