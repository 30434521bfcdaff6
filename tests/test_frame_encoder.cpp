// Chunked, sparse frames (proto Frame.chunks): the encoder's exact error, the
// client's keyed state, and what a subscriber that skips frames decodes.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "codec/delta_codec.h"
#include "codec/frame_encoder.h"
#include "codec/keyed_deltas.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// What a subscriber receives: the chunks of the frame just encoded.
struct SentFrame {
  std::uint64_t version = 0, keyframe_version = 0;
  std::vector<EncodedChunk> chunks;
  double max_error = 0.0;
  std::size_t present = 0;
  std::vector<DeltaChunkView> views() const {
    std::vector<DeltaChunkView> v;
    for (const EncodedChunk& c : chunks) v.push_back({c.first, c.count, c.runs, c.bytes});
    return v;
  }
};

// A session's side: versions and keyframes as the server assigns them.
struct Sender {
  FrameEncoder encoder;
  std::uint64_t version = 0, keyframe = 0;
  SentFrame send(const std::vector<Vec3>& positions, bool force = false) {
    const EncodedFrameSummary s = encoder.encode(positions, force);
    SentFrame f;
    f.version = ++version;
    if (s.keyframe) keyframe = f.version;
    f.keyframe_version = keyframe;
    for (std::size_t c = 0; c < encoder.chunk_count(); ++c)
      if (encoder.chunk(c).kind != EncodedChunk::Kind::kAbsent) f.chunks.push_back(encoder.chunk(c));
    f.max_error = s.max_error;
    f.present = s.present_vertices;
    return f;
  }
};

double max_abs_error(std::span<const float> deltas, const std::vector<Vec3>& positions, const std::vector<Vec3>& rest) {
  double e = 0.0;
  for (std::size_t i = 0; i < rest.size(); ++i)
    for (int k = 0; k < 3; ++k) e = std::max(e, std::abs(double{deltas[3 * i + k]} - (positions[i][k] - rest[i][k])));
  return e;
}

// rest + a smooth whole-body motion of amplitude `a`·diag.
std::vector<Vec3> body_motion(const std::vector<Vec3>& rest, double a, double phase) {
  const double diag = bounding_box_diagonal(rest);
  const double k = 2.0 * std::numbers::pi / diag;
  std::vector<Vec3> p = rest;
  for (Vec3& v : p) v += a * diag * Vec3(std::sin(k * v.y() + phase), std::cos(k * v.z() + phase), std::sin(k * v.x()));
  return p;
}

// `base` with a bump of height h·diag around `centre` (radius r·diag): a local edit.
std::vector<Vec3> bump(const std::vector<Vec3>& base, const std::vector<Vec3>& rest, const Vec3& centre, double r, double h) {
  const double diag = bounding_box_diagonal(rest);
  std::vector<Vec3> p = base;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const double d = (rest[i] - centre).norm() / (r * diag);
    if (d < 1.0) p[i] += h * diag * (1.0 - d * d) * Vec3(0.3, 1.0, -0.2);
  }
  return p;
}

// How far above the exact error a stated one may be: the float32 staging of
// a delta loses up to 2^-24 of the largest, once in the decode's measured
// distance and once added to it; the measure itself rounds in float.
double tight_error_bound(double actual, const std::vector<Vec3>& posed, const std::vector<Vec3>& rest) {
  double largest = 0.0;
  for (std::size_t i = 0; i < rest.size(); ++i) largest = std::max(largest, (posed[i] - rest[i]).cwiseAbs().maxCoeff());
  return actual * (1.0 + 0x1p-21) + 0x1p-23 * largest;
}

TEST(FrameEncoder, ChunkedKeyframeMatchesSingleBufferWithinStatedError) {
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  const std::vector<Vec3>& rest = bunny.positions;
  const double target = 5e-5 * bounding_box_diagonal(rest);
  const std::vector<Vec3> posed = body_motion(rest, 0.05, 0.3);
  Sender s{FrameEncoder(rest, {.chunk_vertices = 500, .bits = 0, .max_error = target})};
  const SentFrame f = s.send(posed);
  ASSERT_EQ(f.keyframe_version, f.version) << "the first frame is a keyframe";
  ASSERT_EQ(f.chunks.size(), 4u);  // 1839 vertices: 3 × 500 + 339
  EXPECT_EQ(f.chunks.back().count, 339u);
  KeyedDeltas client(rest.size());
  client.apply(f.version, f.keyframe_version, f.views(), 2);
  const double actual = max_abs_error(client.deltas(), posed, rest);
  EXPECT_LE(actual, f.max_error);
  EXPECT_LE(f.max_error, tight_error_bound(actual, posed, rest)) << "the stated error is not tight";
  EXPECT_LE(f.max_error, target);

  std::vector<Vec3> deltas(rest.size());
  for (std::size_t i = 0; i < rest.size(); ++i) deltas[i] = posed[i] - rest[i];
  const EncodedDeltas single = encode_deltas(deltas, 14);
  const std::vector<Vec3> one = decode_deltas(single);
  for (std::size_t i = 0; i < rest.size(); ++i)
    for (int k = 0; k < 3; ++k)
      ASSERT_LE(std::abs(double{client.deltas()[3 * i + k]} - one[i][k]), f.max_error + single.max_error) << i;
}

// Randomised deltas at many scales, chunk sizes and bit depths, including
// degenerate ones (all zero, constant, one vertex per chunk): the stated
// error is never below the real decoded error.
TEST(FrameEncoder, StatedErrorNeverBelowDecodedError) {
  std::mt19937 rng(5);
  const std::size_t n = 777;
  std::vector<Vec3> rest(n);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (Vec3& v : rest) v = Vec3(unit(rng), unit(rng), unit(rng));
  struct Case {
    double scale;
    std::uint32_t bits;
    std::uint32_t chunk;
  };
  for (const Case c : {Case{0.0, 14, 100}, Case{1e-7, 0, 64}, Case{1e-3, 8, 1}, Case{1.0, 24, 777}, Case{50.0, 0, 300},
                       Case{2.0, 11, 7}, Case{-1.0, 0, 256}}) {
    SCOPED_TRACE("scale " + std::to_string(c.scale) + " bits " + std::to_string(c.bits) + " chunk " + std::to_string(c.chunk));
    std::vector<Vec3> posed = rest;
    std::uniform_real_distribution<double> d(-std::abs(c.scale), std::abs(c.scale));
    // scale < 0: one constant delta for every vertex.
    for (Vec3& v : posed) v += c.scale < 0 ? Vec3(0.25, -0.5, 0.125) : Vec3(d(rng), d(rng), d(rng));
    const double target = 1e-4;
    Sender s{FrameEncoder(rest, {.chunk_vertices = c.chunk, .bits = c.bits, .max_error = target})};
    KeyedDeltas client(n);
    for (int frame = 0; frame < 3; ++frame) {
      const SentFrame f = s.send(posed);
      client.apply(f.version, f.keyframe_version, f.views());
      const double actual = max_abs_error(client.deltas(), posed, rest);
      ASSERT_LE(actual, f.max_error) << "frame " << frame;
      ASSERT_LE(f.max_error, tight_error_bound(actual, posed, rest)) << "frame " << frame;
      if (c.bits == 0) {
        ASSERT_LE(f.max_error, target);
      }
      // Next frame: half the vertices move a little, half stay.
      for (std::size_t i = 0; i < n; i += 2) posed[i] += Vec3(1e-3, 0.0, -2e-3);
    }
  }
}

TEST(FrameEncoder, SparseFrameAppliedToItsKeyframeEqualsFullFrame) {
  const TriMesh sphere = test::icosphere(4);
  const std::vector<Vec3>& rest = sphere.positions;
  const double target = 5e-5 * bounding_box_diagonal(rest);
  Sender s{FrameEncoder(rest, {.chunk_vertices = 256, .bits = 0, .max_error = target})};
  const std::vector<Vec3> posed = body_motion(rest, 0.03, 0.0);
  const SentFrame key = s.send(posed);
  KeyedDeltas client(rest.size());
  client.apply(key.version, key.keyframe_version, key.views());

  const std::vector<Vec3> edited = bump(posed, rest, rest[0], 0.15, 0.02);
  const SentFrame sparse = s.send(edited);
  EXPECT_EQ(sparse.keyframe_version, key.version);
  EXPECT_LT(sparse.present, rest.size() / 4) << "a local edit carries few vertices";
  std::size_t bytes = 0;
  for (const EncodedChunk& c : sparse.chunks) bytes += c.bytes.size() + 4 * c.runs.size();
  std::printf("[ sparse   ] %zu of %zu vertices present, %zu bytes (%.3f B/vertex)\n", sparse.present, rest.size(), bytes,
              double(bytes) / rest.size());
  client.apply(sparse.version, sparse.keyframe_version, sparse.views());

  // The same positions as a full frame, from a fresh encoder.
  Sender full{FrameEncoder(rest, {.chunk_vertices = 256, .bits = 0, .max_error = target})};
  const SentFrame whole = full.send(edited);
  KeyedDeltas other(rest.size());
  other.apply(whole.version, whole.keyframe_version, whole.views());
  EXPECT_LE(max_abs_error(client.deltas(), edited, rest), sparse.max_error);
  for (std::size_t i = 0; i < 3 * rest.size(); ++i)
    ASSERT_LE(std::abs(client.deltas()[i] - other.deltas()[i]), sparse.max_error + whole.max_error) << i / 3;
}

// A subscriber with a mailbox of one skips frames: whatever sparse frame it
// gets is relative to the keyframe it holds, and a later sparse frame
// restores the vertices an earlier one changed.
TEST(FrameEncoder, SkippedFramesAndMovingEditsDecodeCorrectly) {
  const TriMesh sphere = test::icosphere(4);
  const std::vector<Vec3>& rest = sphere.positions;
  const double target = 5e-5 * bounding_box_diagonal(rest);
  Sender s{FrameEncoder(rest, {.chunk_vertices = 128, .bits = 0, .max_error = target})};
  KeyedDeltas all(rest.size()), skipping(rest.size());
  const SentFrame key = s.send(rest);
  all.apply(key.version, key.keyframe_version, key.views());
  skipping.apply(key.version, key.keyframe_version, key.views());
  std::vector<Vec3> posed;
  for (int frame = 0; frame < 6; ++frame) {
    // The bump walks around the sphere: frame k's edit is gone in frame k+1.
    posed = bump(rest, rest, rest[static_cast<std::size_t>(frame * 97) % rest.size()], 0.2, 0.03);
    const SentFrame f = s.send(posed);
    ASSERT_EQ(f.keyframe_version, key.version);
    all.apply(f.version, f.keyframe_version, f.views());
    ASSERT_LE(max_abs_error(all.deltas(), posed, rest), f.max_error) << "frame " << f.version;
    if (frame % 3 == 2) {  // the skipping client reads every third frame
      skipping.apply(f.version, f.keyframe_version, f.views());
      ASSERT_LE(max_abs_error(skipping.deltas(), posed, rest), f.max_error) << "frame " << f.version;
    }
  }
}

TEST(FrameEncoder, WholeBodyMotionMakesKeyframesAndRequestsForce) {
  const TriMesh sphere = test::icosphere(3);
  const std::vector<Vec3>& rest = sphere.positions;
  Sender s{FrameEncoder(rest, {.chunk_vertices = 100, .bits = 14})};
  for (int frame = 0; frame < 3; ++frame) {
    const SentFrame f = s.send(body_motion(rest, 0.05, 0.4 * frame));
    EXPECT_EQ(f.keyframe_version, f.version) << "every vertex moved: a keyframe";
    EXPECT_EQ(f.present, rest.size());
  }
  const SentFrame same = s.send(body_motion(rest, 0.05, 0.8));
  EXPECT_NE(same.keyframe_version, same.version) << "nothing moved: a sparse frame";
  EXPECT_EQ(same.present, 0u);
  const SentFrame forced = s.send(body_motion(rest, 0.05, 0.8), /*force=*/true);
  EXPECT_EQ(forced.keyframe_version, forced.version);
}

TEST(KeyedDeltas, RejectsWhatCannotBeDecodedAndKeepsItsKeyframe) {
  const TriMesh sphere = test::icosphere(3);
  const std::vector<Vec3>& rest = sphere.positions;
  const std::uint32_t n = static_cast<std::uint32_t>(rest.size());
  Sender s{FrameEncoder(rest, {.chunk_vertices = 200, .bits = 12})};
  const std::vector<Vec3> posed = body_motion(rest, 0.05, 0.1);
  const SentFrame key = s.send(posed);
  KeyedDeltas client(n);
  client.apply(key.version, key.keyframe_version, key.views());
  const std::vector<float> held(client.deltas().begin(), client.deltas().end());
  const SentFrame sparse = s.send(bump(posed, rest, rest[3], 0.2, 0.05));
  ASSERT_NE(sparse.keyframe_version, sparse.version);

  auto expect_error = [&](std::uint64_t version, std::uint64_t keyframe, std::vector<DeltaChunkView> chunks, const char* what) {
    EXPECT_THROW(client.apply(version, keyframe, chunks), DeltaCodecError) << what;
    EXPECT_TRUE(std::equal(held.begin(), held.end(), client.deltas().begin())) << what << ": the keyframe changed";
  };
  expect_error(sparse.version, sparse.keyframe_version + 1, sparse.views(), "relative to another keyframe");
  std::vector<DeltaChunkView> v = key.views();
  v.pop_back();
  expect_error(9, 9, v, "a keyframe missing a chunk");
  v = key.views();
  std::swap(v[0], v[1]);
  expect_error(9, 9, v, "chunks out of order");
  v = key.views();
  v.back().count += 1;
  expect_error(9, 9, v, "a chunk past the mesh");
  v = key.views();
  std::string broken(v[1].bytes);
  broken.resize(broken.size() / 2);
  v[1].bytes = broken;
  expect_error(9, 9, v, "a truncated chunk");
  v = sparse.views();
  const std::vector<std::uint32_t> long_runs = {0, 100000};
  v[0].runs = long_runs;
  expect_error(sparse.version, sparse.keyframe_version, v, "runs past their range");
  const std::vector<std::uint32_t> odd_runs = {1};
  v = sparse.views();
  v[0].runs = odd_runs;
  expect_error(sparse.version, sparse.keyframe_version, v, "an odd number of runs");
  // And the good sparse frame still applies after all that.
  EXPECT_NO_THROW(client.apply(sparse.version, sparse.keyframe_version, sparse.views()));
}

// After a motion that leaves half the mesh moved away from the keyframe, local
// edits would carry that half forever; a fresh keyframe is made once what it
// saves adds up to a whole frame, and local frames are small again after it.
TEST(FrameEncoder, AStaleKeyframeIsRenewedWhenItCostsMoreThanAFrame) {
  const TriMesh sphere = test::icosphere(4);
  const std::vector<Vec3>& rest = sphere.positions;
  const double target = 5e-5 * bounding_box_diagonal(rest);
  Sender s{FrameEncoder(rest, {.chunk_vertices = 256, .bits = 0, .max_error = target})};
  s.send(rest);  // keyframe: the rest pose
  std::vector<Vec3> posed = rest;
  for (std::size_t i = 0; i < rest.size(); ++i)
    if (rest[i].x() > 0.0) posed[i] += Vec3(0.1, 0.05, 0.0) * rest[i].x();  // half the sphere moves once
  const SentFrame half = s.send(posed);
  EXPECT_GT(half.present, rest.size() / 4);
  std::vector<std::size_t> present;
  std::vector<bool> keyframe;
  for (int frame = 0; frame < 8; ++frame) {
    const SentFrame f = s.send(bump(posed, rest, rest[5], 0.1, 0.01 * (frame + 1)));
    present.push_back(f.present);
    keyframe.push_back(f.keyframe_version == f.version);
  }
  const auto first_key = std::find(keyframe.begin(), keyframe.end(), true);
  ASSERT_NE(first_key, keyframe.end()) << "the stale keyframe was never renewed";
  EXPECT_LE(first_key - keyframe.begin(), 4);
  EXPECT_LT(present.back(), rest.size() / 10) << "local edits are small again after the new keyframe";
  EXPECT_EQ(std::count(keyframe.begin(), keyframe.end(), true), 1) << "one renewal is enough";
}

TEST(FrameEncoder, AChunkLeftOutShowsTheKeyframeToTheNextFrame) {
  // Clients keep the keyframe's deltas where a frame leaves a chunk out; the
  // encoder does too (without copying them), so the next frame counts what
  // moved since the last one against the keyframe there, not against an
  // older frame's deltas.
  const std::vector<Vec3> rest = test::icosphere(4).positions;
  const double diag = bounding_box_diagonal(rest);
  FrameEncoder encoder(rest, {.chunk_vertices = 256, .bits = 0, .max_error = 5e-5 * diag});
  ASSERT_GE(encoder.chunk_count(), 3u);
  const std::vector<Vec3> keyed = body_motion(rest, 0.02, 0.3);  // every delta non-zero
  ASSERT_TRUE(encoder.encode(keyed, true).keyframe);
  const auto moved_chunk = [&](const std::vector<Vec3>& from, std::size_t c) {
    std::vector<Vec3> p = from;
    for (std::size_t i = encoder.chunk(c).first; i < encoder.chunk(c).first + encoder.chunk(c).count; ++i)
      p[i] += Vec3(0.01 * diag, 0.0, 0.0);
    return p;
  };
  const std::vector<Vec3> first_moved = moved_chunk(keyed, 0);
  encoder.encode(first_moved, false);
  ASSERT_NE(encoder.chunk(0).kind, EncodedChunk::Kind::kAbsent);
  ASSERT_EQ(encoder.chunk(1).kind, EncodedChunk::Kind::kAbsent);
  encoder.encode(first_moved, false);  // nothing moved since
  for (std::size_t c = 0; c < encoder.chunk_count(); ++c)
    EXPECT_EQ(encoder.chunk(c).moved_since_last, 0u) << "chunk " << c;
  encoder.encode(moved_chunk(first_moved, 1), false);  // now chunk 1 moves, and only it
  EXPECT_EQ(encoder.chunk(0).moved_since_last, 0u);
  EXPECT_EQ(encoder.chunk(1).moved_since_last, encoder.chunk(1).count);
  EXPECT_EQ(encoder.chunk(2).moved_since_last, 0u);
}

TEST(FrameEncoder, StagingFromASharedPoolGivesTheSameFramesAndHoldsNothingBetween) {
  // Two sessions' encoders sharing one pool, against one with buffers of its
  // own: the same bytes frame after frame (dense, sparse, absent chunks), and
  // between frames every staging buffer is back in the pool.
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  const std::vector<Vec3>& rest = bunny.positions;
  const double target = 5e-5 * bounding_box_diagonal(rest);
  auto pool = std::make_shared<BufferPool<float>>(16);
  const FrameEncoderOptions own{.chunk_vertices = 256, .bits = 0, .max_error = target};
  FrameEncoderOptions pooled = own;
  pooled.staging = pool;
  Sender alone{FrameEncoder(rest, own)}, a{FrameEncoder(rest, pooled)}, b{FrameEncoder(rest, pooled)};
  const Vec3 centre = rest[rest.size() / 3];
  for (int frame = 0; frame < 6; ++frame) {
    const std::vector<Vec3> posed = frame < 2 ? body_motion(rest, 0.02, 0.1 * frame)
                                              : bump(body_motion(rest, 0.02, 0.1), rest, centre, 0.1, 0.01 * frame);
    const SentFrame expected = alone.send(posed), got_a = a.send(posed), got_b = b.send(posed);
    for (const SentFrame* got : {&got_a, &got_b}) {
      ASSERT_EQ(got->chunks.size(), expected.chunks.size()) << "frame " << frame;
      for (std::size_t c = 0; c < expected.chunks.size(); ++c) {
        EXPECT_EQ(got->chunks[c].bytes, expected.chunks[c].bytes) << "frame " << frame << " chunk " << c;
        EXPECT_EQ(got->chunks[c].runs, expected.chunks[c].runs) << "frame " << frame << " chunk " << c;
      }
      EXPECT_EQ(got->max_error, expected.max_error);
    }
    EXPECT_GT(pool->free_buffers(), 0u);
  }
  // encode() stages one chunk at a time, so one buffer went round.
  EXPECT_EQ(pool->free_buffers(), 1u);
  // A session quantizes every chunk before encoding them (in parallel): each
  // holds a buffer until its encode, then all are back.
  const std::vector<Vec3> posed = body_motion(rest, 0.03, 0.7);
  const SentFrame expected = alone.send(posed, true);
  a.encoder.begin(true);
  for (std::size_t c = 0; c < a.encoder.chunk_count(); ++c) a.encoder.quantize_chunk(c, posed);
  EXPECT_EQ(pool->free_buffers(), 0u);
  for (std::size_t c = 0; c < a.encoder.chunk_count(); ++c) a.encoder.encode_chunk(c);
  a.encoder.finish();
  EXPECT_EQ(pool->free_buffers(), a.encoder.chunk_count());
  for (std::size_t c = 0; c < expected.chunks.size(); ++c) EXPECT_EQ(a.encoder.chunk(c).bytes, expected.chunks[c].bytes) << c;
}

TEST(FrameEncoder, ChunksEncodedTogetherGiveTheSameBytes) {
  // As a session's tasks take them: every chunk quantized, then groups of 3
  // encoded together (the last group short), against one chunk at a time;
  // dense, sparse and absent chunks alike.
  const TriMesh bunny = test::shipped_mesh("bunny_small.obj");
  const std::vector<Vec3>& rest = bunny.positions;
  const FrameEncoderOptions options{.chunk_vertices = 200, .bits = 0, .max_error = 5e-5 * bounding_box_diagonal(rest)};
  Sender alone{FrameEncoder(rest, options)};
  FrameEncoder grouped(rest, options);
  ASSERT_GT(grouped.chunk_count() % 3, 0u);
  const Vec3 centre = rest[rest.size() / 3];
  int sparse = 0;
  for (int frame = 0; frame < 5; ++frame) {
    const std::vector<Vec3> posed = frame < 2 ? body_motion(rest, 0.02, 0.1 * frame)
                                              : bump(body_motion(rest, 0.02, 0.1), rest, centre, 0.1, 0.01 * frame);
    alone.send(posed);
    grouped.begin(false);
    for (std::size_t c = 0; c < grouped.chunk_count(); ++c) grouped.quantize_chunk(c, posed);
    for (std::size_t c = 0; c < grouped.chunk_count(); c += 3)
      grouped.encode_chunks(c, std::min<std::size_t>(3, grouped.chunk_count() - c));
    grouped.finish();
    for (std::size_t c = 0; c < grouped.chunk_count(); ++c) {
      ASSERT_EQ(grouped.chunk(c).kind, alone.encoder.chunk(c).kind) << "frame " << frame << " chunk " << c;
      EXPECT_EQ(grouped.chunk(c).bytes, alone.encoder.chunk(c).bytes) << "frame " << frame << " chunk " << c;
      sparse += grouped.chunk(c).kind == EncodedChunk::Kind::kSparse;
    }
  }
  EXPECT_GT(sparse, 0);
  EXPECT_THROW(grouped.encode_chunks(grouped.chunk_count() - 1, 2), std::out_of_range);
}

TEST(FrameEncoder, RejectsBadOptions) {
  const std::vector<Vec3> rest(10, Vec3(1.0, 2.0, 3.0));
  EXPECT_THROW(FrameEncoder(rest, {.chunk_vertices = 0, .max_error = 1e-3}), std::invalid_argument);
  EXPECT_THROW(FrameEncoder(rest, {.bits = 7}), std::invalid_argument);
  EXPECT_THROW(FrameEncoder(rest, {.bits = 0, .max_error = 0.0}), std::invalid_argument);
  for (int speed : {-1, 11})
    EXPECT_THROW(FrameEncoder(rest, {.max_error = 1e-3, .speed = speed}), std::invalid_argument) << speed;
  EXPECT_NO_THROW(FrameEncoder(rest, {.max_error = 1e-3, .speed = 10}));
}

}  // namespace
}  // namespace filigree
