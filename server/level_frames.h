#pragma once
// One session's frames at one level of detail (proto DetailLevel): the
// level's vertices' deltas, taken from the same computed positions as the
// full frame, encoded once per frame for every stream at the level, chunked
// and sparse against the level's own keyframes like full frames.

#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>

#include "codec/frame_encoder.h"
#include "filigree/v1/filigree.pb.h"
#include "server/level_geometry.h"

namespace filigree::server {

struct PublishedFrame;

// Copies the chunks `encoder` just finished into `out` (moving their bytes)
// and returns the most quantization bits any uses.
std::uint32_t move_chunks(FrameEncoder& encoder, v1::Frame& out);

class LevelFrames {
 public:
  // `options` as the session's full frames (the same max_error and bits).
  LevelFrames(std::shared_ptr<const LevelGeometry> geometry, const FrameEncoderOptions& options);

  const LevelGeometry& geometry() const { return *geometry_; }
  const std::shared_ptr<const LevelGeometry>& shared_geometry() const { return geometry_; }

  // Starts the level's frame from `positions` (the full frame's posed
  // positions, original order, read only here): gathers and quantizes its
  // vertices. The first frame, and one after discard(), is a keyframe.
  // Throws DeltaCodecError as FrameEncoder.
  void quantize(std::span<const Vec3> positions, bool force_keyframe);
  // Then Draco-encodes it.
  void encode();

  // The frame encode() made, as published: `common` (version, changes) with
  // the level's chunks and stats; relative to the level's latest keyframe.
  std::shared_ptr<const PublishedFrame> publish(const v1::Frame& common, const v1::FrameStats& stats,
                                                const std::unordered_map<std::uint64_t, std::uint64_t>& pose_of_driver,
                                                const std::shared_ptr<BufferPool<char>>& wire_pool);

  // A frame failed after encode(): the next one must be a keyframe.
  void discard();

  std::uint64_t frames_encoded() const { return frames_encoded_; }

 private:
  std::shared_ptr<const LevelGeometry> geometry_;
  FrameEncoder encoder_;
  std::vector<Vec3> positions_;  // the level's, gathered for the encoder
  EncodedFrameSummary summary_;
  double encode_ms_ = 0.0;  // quantize() and encode()
  std::shared_ptr<const PublishedFrame> keyframe_;
  bool need_keyframe_ = true;
  std::uint64_t frames_encoded_ = 0;
};

}  // namespace filigree::server
