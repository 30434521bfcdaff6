#pragma once
// A frame's wire bytes, serialized once and written by every stream that
// sends it (encoded once per frame, shared by every subscriber).
// At 1.25M vertices a frame is ~1 MB: gRPC serialized it once per stream,
// each time into freshly allocated (so freshly faulted-in) memory, ~1.5 ms
// a stream, and a driver's stream first deep-copied the message (~0.7 ms)
// to set its pose id. Here the bytes go into a pooled buffer, and a
// driver's stream appends its pose id as a second slice: protobuf parsing
// keeps the last value of a repeated scalar field, so the two slices read
// as the frame with that pose id.

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <string>
#include <memory>
#include <mutex>
#include <optional>
#include <utility>

#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/slice.h>

#include "filigree/v1/filigree.pb.h"
#include "util/buffer_pool.h"

namespace filigree::server {

class SerializedFrame {
 public:
  // Serializes `frame` into a buffer taken from `pool` (null: a pool of its
  // own). The buffer goes back to the pool once this object and every
  // ByteBuffer made from it are gone (gRPC may hold one after a stream has
  // ended). Throws std::runtime_error if the frame cannot be serialized
  // (over 2 GiB).
  SerializedFrame(const v1::Frame& frame, std::shared_ptr<BufferPool<char>> pool);

  // What one stream writes: the frame itself (pose_id 0, clip_seconds 0),
  // or the frame with its pose_id and clip_seconds fields set to these.
  // Shares the serialized bytes.
  grpc::ByteBuffer for_stream(std::uint64_t pose_id, double clip_seconds = 0.0) const;
  std::size_t size() const { return body_.size(); }
  const grpc::Slice& bytes() const { return body_; }

 private:
  grpc::Slice body_;
};

// A slice over `bytes`, which it owns until gRPC lets go of the last slice
// over them (empty bytes: an empty slice).
grpc::Slice owned_slice(std::string bytes);

// Appends `v` as a protobuf varint (for tags and lengths written by hand).
void append_varint(std::string& out, std::uint64_t v);

// A published message's wire bytes, serialized by the first caller that
// needs them and shared after (GetOverlays: at 1.25M vertices a frame's
// overlays are megabytes, which every poll copied and serialized).
// Thread-safe; the message must not change once published.
class SerializedOnce {
 public:
  explicit SerializedOnce(std::shared_ptr<const google::protobuf::MessageLite> message) : message_(std::move(message)) {}
  grpc::ByteBuffer bytes() const;

 private:
  std::shared_ptr<const google::protobuf::MessageLite> message_;
  mutable std::once_flag once_;
  mutable grpc::Slice bytes_;
};

// A frame embedded in an answer as a message field (SessionState.frame,
// .keyframe): its field number and its bytes.
struct FrameField {
  std::uint32_t number;
  const SerializedFrame* frame;
};

// The wire bytes of a message: `head` (its other fields, serialized), then
// each frame as its length-delimited field, sharing the frames' bytes
// (GetState's answer: at 1.25M vertices a frame and its keyframe are ~2 MB,
// which the typed answer copied, and gRPC serialized, on every call).
grpc::ByteBuffer message_with_frames(std::string head, std::initializer_list<FrameField> frames);

// A frame's SerializedFrame, made by the first stream that needs it and
// shared after; thread-safe. A copy starts empty (it may serialize a
// different message).
class LazySerializedFrame {
 public:
  LazySerializedFrame() = default;
  LazySerializedFrame(const LazySerializedFrame&) {}
  LazySerializedFrame& operator=(const LazySerializedFrame&) = delete;

  // `frame` must be the same message (unchanged) at every call.
  const SerializedFrame& get(const v1::Frame& frame, const std::shared_ptr<BufferPool<char>>& pool) const;

 private:
  mutable std::mutex mutex_;
  mutable std::optional<SerializedFrame> value_;
};

}  // namespace filigree::server
