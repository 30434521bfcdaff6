#include "filigree/frame_decoder.h"

#include "codec/delta_codec.h"
#include "filigree/client_error.h"

namespace filigree {

FrameDecoder::FrameDecoder(std::vector<float> rest_positions) : rest_(std::move(rest_positions)) {
  if (rest_.size() % 3 != 0) throw std::invalid_argument("FrameDecoder: rest positions are not a multiple of 3");
}

DecodedFrame FrameDecoder::decode(const v1::Frame& frame) const {
  const std::string where = "frame " + std::to_string(frame.version()) + ": ";
  if (frame.vertex_count() != vertex_count())
    throw ClientError(grpc::StatusCode::DATA_LOSS, where + "has " + std::to_string(frame.vertex_count()) +
                                                       " vertices, the rest mesh " + std::to_string(vertex_count()));
  EncodedDeltas encoded;
  encoded.bytes = frame.deltas();
  encoded.count = frame.vertex_count();
  encoded.bits = frame.quantization_bits();
  encoded.min = frame.delta_min();
  encoded.range = frame.delta_range();
  encoded.max_error = frame.max_error();
  std::vector<Vec3> deltas;
  try {
    deltas = decode_deltas(encoded);
  } catch (const DeltaCodecError& e) {
    throw ClientError(grpc::StatusCode::DATA_LOSS, where + e.what());
  }
  if (deltas.size() != vertex_count())  // decode_deltas promises this; a wrong frame must not crash us
    throw ClientError(grpc::StatusCode::DATA_LOSS, where + "decoded " + std::to_string(deltas.size()) + " deltas");

  DecodedFrame out;
  out.version = frame.version();
  out.pose_id = frame.pose_id();
  out.max_error = frame.max_error();
  out.stats = frame.stats();
  out.changes.assign(frame.changes().begin(), frame.changes().end());
  out.encoded_bytes = frame.deltas().size();
  out.positions.resize(rest_.size());
  for (std::size_t i = 0; i < deltas.size(); ++i)
    for (int c = 0; c < 3; ++c)
      out.positions[3 * i + c] = rest_[3 * i + c] + static_cast<float>(deltas[i][c]);
  return out;
}

}  // namespace filigree
