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

DecodedFrame FrameDecoder::decode(const v1::Frame& frame) {
  const std::string where = "frame " + std::to_string(frame.version()) + ": ";
  if (frame.vertex_count() != vertex_count())
    throw ClientError(grpc::StatusCode::DATA_LOSS, where + "has " + std::to_string(frame.vertex_count()) +
                                                       " vertices, the rest mesh " + std::to_string(vertex_count()));
  DecodedFrame out;
  out.positions.resize(rest_.size());
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
      for (std::size_t i = 0; i < rest_.size(); ++i) out.positions[i] = rest_[i] + deltas[i];
    } else {
      decode_deltas_into(frame.deltas(), frame.vertex_count(), out.positions);
      for (std::size_t i = 0; i < rest_.size(); ++i) out.positions[i] += rest_[i];
      out.encoded_bytes = frame.deltas().size();
      out.present_vertices = vertex_count();
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
  return out;
}

}  // namespace filigree
