#include "filigree/frame_decoder.h"

#include <algorithm>
#include <thread>

#include "codec/delta_codec.h"
#include "codec/keyed_deltas.h"
#include "filigree/client_error.h"

namespace filigree {

FrameDecoder::FrameDecoder(std::vector<float> rest_positions, unsigned threads)
    : rest_(std::move(rest_positions)), threads_(threads ? threads : std::max(1u, std::thread::hardware_concurrency())) {
  if (rest_.size() % 3 != 0) throw std::invalid_argument("FrameDecoder: rest positions are not a multiple of 3");
  keyed_ = std::make_unique<KeyedDeltas>(rest_.size() / 3);
}

FrameDecoder::~FrameDecoder() = default;
FrameDecoder::FrameDecoder(FrameDecoder&&) noexcept = default;
FrameDecoder& FrameDecoder::operator=(FrameDecoder&&) noexcept = default;

const DecodedLevel& FrameDecoder::set_level(const v1::DetailLevel& level) {
  auto decoded = std::make_shared<const DecodedLevel>(decode_level(level, rest_));
  auto keyed = std::make_unique<KeyedDeltas>(decoded->vertex_count);
  level_ = std::move(decoded);
  keyed_ = std::move(keyed);
  return *level_;
}

DecodedFrame FrameDecoder::decode(const v1::Frame& frame) {
  const std::string where = "frame " + std::to_string(frame.version()) + ": ";
  if (frame.has_level())
    throw ClientError(grpc::StatusCode::INVALID_ARGUMENT,
                      where + "starts a level of detail and carries no deltas: give it to FrameDecoder::set_level");
  // At a level, its vertices and rest positions; at full detail, the mesh's.
  const bool at_level = level_ && !level_->full_detail;
  const std::vector<float>& rest = at_level ? level_->rest_positions : rest_;
  const std::size_t count = rest.size() / 3;
  const std::uint32_t level_vertices = at_level ? level_->vertex_count : 0;
  if (frame.level_vertices() != level_vertices)
    throw ClientError(grpc::StatusCode::DATA_LOSS,
                      where + "is at the level of " + std::to_string(frame.level_vertices()) +
                          " vertices (0: full detail), the stream at " + std::to_string(level_vertices));
  if (frame.vertex_count() != count)
    throw ClientError(grpc::StatusCode::DATA_LOSS,
                      where + "has " + std::to_string(frame.vertex_count()) + " vertices, " +
                          (at_level ? "its level " : "the rest mesh ") + std::to_string(count));
  DecodedFrame out;
  out.positions.resize(rest.size());
  const bool chunked = frame.chunks_size() > 0 || frame.keyframe_version() != 0;
  try {
    if (chunked) {
      std::vector<DeltaChunkView> views;
      views.reserve(static_cast<std::size_t>(frame.chunks_size()));
      for (const v1::DeltaChunk& c : frame.chunks()) {
        views.push_back({c.first_vertex(), c.vertex_count(), {c.runs().data(), static_cast<std::size_t>(c.runs_size())}, c.deltas()});
        out.encoded_bytes += c.deltas().size() + 4 * static_cast<std::size_t>(c.runs_size());
        std::uint64_t present = c.vertex_count();
        if (c.runs_size() > 0) {
          present = 0;
          for (int r = 1; r < c.runs_size(); r += 2) present += c.runs(r);
        }
        out.present_vertices += present;
      }
      keyed_->apply(frame.version(), frame.keyframe_version(), views, threads_);
      out.keyframe = frame.version() == frame.keyframe_version();
      const std::span<const float> deltas = keyed_->deltas();
      for (std::size_t i = 0; i < rest.size(); ++i) out.positions[i] = rest[i] + deltas[i];
    } else {
      decode_deltas_into(frame.deltas(), frame.vertex_count(), out.positions);
      for (std::size_t i = 0; i < rest.size(); ++i) out.positions[i] += rest[i];
      out.encoded_bytes = frame.deltas().size();
      out.present_vertices = count;
    }
  } catch (const DeltaCodecError& e) {
    throw ClientError(grpc::StatusCode::DATA_LOSS, where + e.what());
  }
  out.version = frame.version();
  out.pose_id = frame.pose_id();
  out.max_error = frame.max_error();
  out.clip_seconds = frame.clip_seconds();
  out.stats = frame.stats();
  out.changes.assign(frame.changes().begin(), frame.changes().end());
  out.level = level_;
  return out;
}

}  // namespace filigree
