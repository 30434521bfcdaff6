#include "server/level_frames.h"

#include <algorithm>
#include <chrono>
#include <utility>

#include "codec/delta_codec.h"
#include "server/session.h"

namespace filigree::server {

std::uint32_t move_chunks(FrameEncoder& encoder, v1::Frame& out) {
  std::uint32_t bits = 0;
  for (std::size_t c = 0; c < encoder.chunk_count(); ++c) {
    EncodedChunk& chunk = encoder.chunk(c);
    if (chunk.kind == EncodedChunk::Kind::kAbsent) continue;
    v1::DeltaChunk& d = *out.add_chunks();
    d.set_first_vertex(chunk.first);
    d.set_vertex_count(chunk.count);
    d.mutable_runs()->Add(chunk.runs.begin(), chunk.runs.end());
    d.set_deltas(std::move(chunk.bytes));
    d.set_quantization_bits(chunk.quantization.bits);
    d.set_delta_min(chunk.quantization.min);
    d.set_delta_range(chunk.quantization.range);
    bits = std::max(bits, chunk.quantization.bits);
  }
  return bits;
}

LevelFrames::LevelFrames(std::shared_ptr<const LevelGeometry> geometry, const FrameEncoderOptions& options)
    : geometry_(std::move(geometry)), encoder_(geometry_->rest, options) {}

namespace {
double ms_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}
}  // namespace

void LevelFrames::quantize(std::span<const Vec3> positions, bool force_keyframe) {
  const auto start = std::chrono::steady_clock::now();
  const std::vector<Index>& ids = geometry_->original_ids;
  positions_.resize(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) positions_[i] = positions[ids[i]];
  encoder_.begin(force_keyframe || std::exchange(need_keyframe_, false));
  for (std::size_t c = 0; c < encoder_.chunk_count(); ++c) encoder_.quantize_chunk(c, positions_);
  encode_ms_ = ms_since(start);
}

void LevelFrames::encode() {
  const auto start = std::chrono::steady_clock::now();
  encoder_.encode_chunks(0, encoder_.chunk_count());
  summary_ = encoder_.finish();
  encode_ms_ += ms_since(start);
  ++frames_encoded_;
}

void LevelFrames::discard() { need_keyframe_ = true; }

std::shared_ptr<const PublishedFrame> LevelFrames::publish(
    const v1::Frame& common, const v1::FrameStats& stats,
    const std::unordered_map<std::uint64_t, std::uint64_t>& pose_of_driver,
    const std::shared_ptr<BufferPool<char>>& wire_pool) {
  auto published = std::make_shared<PublishedFrame>();
  published->pose_of_driver = pose_of_driver;
  published->wire_pool = wire_pool;
  published->geometry = geometry_;
  v1::Frame& out = published->frame;
  out = common;
  out.set_vertex_count(geometry_->vertex_count);
  out.set_level_vertices(geometry_->vertex_count);
  out.set_quantization_bits(move_chunks(encoder_, out));
  out.set_max_error(float_at_least(summary_.max_error));
  *out.mutable_stats() = stats;
  out.mutable_stats()->set_encode_ms(encode_ms_);
  out.mutable_stats()->set_encoded_bytes(static_cast<std::uint32_t>(summary_.bytes));
  out.mutable_stats()->set_present_vertices(static_cast<std::uint32_t>(summary_.present_vertices));
  if (summary_.keyframe || !keyframe_) {
    out.set_keyframe_version(out.version());
  } else {
    out.set_keyframe_version(keyframe_->frame.version());
    published->keyframe = keyframe_;
  }
  if (!published->keyframe) keyframe_ = published;
  return published;
}

}  // namespace filigree::server
