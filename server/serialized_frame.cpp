#include "server/serialized_frame.h"

#include <array>
#include <bit>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace filigree::server {
namespace {

// Owns a pooled buffer for as long as gRPC holds the slice over it.
struct PooledBytes {
  std::shared_ptr<BufferPool<char>> pool;
  std::vector<char> bytes;
};

void give_back(void* user_data) {
  auto* owned = static_cast<PooledBytes*>(user_data);
  owned->pool->give(std::move(owned->bytes));
  delete owned;
}

// Frame.pose_id (field 2, varint): the wire bytes of that one field.
constexpr std::uint8_t kPoseIdTag = (2 << 3) | 0;
// Frame.clip_seconds (field 14, a double: wire type 1, 8 bytes).
constexpr std::uint8_t kClipSecondsTag = (14 << 3) | 1;

}  // namespace

SerializedFrame::SerializedFrame(const v1::Frame& frame, std::shared_ptr<BufferPool<char>> pool) {
  const std::size_t size = frame.ByteSizeLong();
  if (size > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw std::runtime_error("a frame of " + std::to_string(size) + " bytes is over protobuf's 2 GiB limit");
  if (size == 0) return;  // an empty message: an empty slice
  if (!pool) pool = std::make_shared<BufferPool<char>>(0);  // nobody to share with
  auto owned = std::make_unique<PooledBytes>(PooledBytes{std::move(pool), {}});
  owned->bytes = owned->pool->take(size);
  auto* data = reinterpret_cast<std::uint8_t*>(owned->bytes.data());
  // The size was just computed: the message must not change meanwhile (it
  // is published, so const).
  if (static_cast<std::size_t>(frame.SerializeWithCachedSizesToArray(data) - data) != size) {
    owned->pool->give(std::move(owned->bytes));
    throw std::logic_error("a frame changed while it was serialized");
  }
  body_ = grpc::Slice(data, size, give_back, owned.release());
}

grpc::ByteBuffer SerializedFrame::for_stream(std::uint64_t pose_id, double clip_seconds) const {
  if (pose_id == 0 && clip_seconds == 0.0) return grpc::ByteBuffer(&body_, 1);
  // At most 11 + 9 bytes: within std::string's small buffer (15) or one allocation.
  std::string tail;
  if (pose_id != 0) {
    tail.push_back(static_cast<char>(kPoseIdTag));
    append_varint(tail, pose_id);
  }
  if (clip_seconds != 0.0) {
    tail.push_back(static_cast<char>(kClipSecondsTag));
    const auto bits = std::bit_cast<std::uint64_t>(clip_seconds);
    for (int i = 0; i < 8; ++i) tail.push_back(static_cast<char>(bits >> (8 * i)));  // little-endian, as protobuf's fixed64
  }
  const std::array<grpc::Slice, 2> slices{body_, grpc::Slice(tail)};
  return grpc::ByteBuffer(slices.data(), slices.size());
}

grpc::Slice owned_slice(std::string bytes) {
  if (bytes.empty()) return grpc::Slice();
  auto* owned = new std::string(std::move(bytes));
  return grpc::Slice(owned->data(), owned->size(), [](void* p) { delete static_cast<std::string*>(p); }, owned);
}

void append_varint(std::string& out, std::uint64_t v) {
  for (; v >= 0x80; v >>= 7) out.push_back(static_cast<char>(v | 0x80));
  out.push_back(static_cast<char>(v));
}

grpc::ByteBuffer SerializedOnce::bytes() const {
  std::call_once(once_, [this] { bytes_ = owned_slice(message_->SerializeAsString()); });
  return grpc::ByteBuffer(&bytes_, 1);
}

grpc::ByteBuffer message_with_frames(std::string head, std::initializer_list<FrameField> frames) {
  std::vector<grpc::Slice> slices;
  for (const FrameField& f : frames) {
    append_varint(head, std::uint64_t{f.number} << 3 | 2);  // length-delimited
    append_varint(head, f.frame->size());
    slices.emplace_back(head);
    head.clear();
    if (f.frame->size() > 0) slices.push_back(f.frame->bytes());  // an empty one adds nothing
  }
  if (!head.empty() || slices.empty()) slices.emplace_back(head);
  return grpc::ByteBuffer(slices.data(), slices.size());
}

const SerializedFrame& LazySerializedFrame::get(const v1::Frame& frame, const std::shared_ptr<BufferPool<char>>& pool) const {
  std::lock_guard lock(mutex_);
  if (!value_) value_.emplace(frame, pool);
  return *value_;
}

}  // namespace filigree::server
