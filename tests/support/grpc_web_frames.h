#pragma once
// The gRPC-Web wire format for tests: a frame is a flag byte (0x80: the
// trailer), a 32-bit big-endian length and the payload.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace filigree::test {

inline std::string frame_bytes(std::uint8_t flags, const std::string& payload) {
  std::string out(1, static_cast<char>(flags));
  const auto n = static_cast<std::uint32_t>(payload.size());
  for (int s : {24, 16, 8, 0}) out += static_cast<char>((n >> s) & 0xff);
  return out + payload;
}

struct Frame {
  std::uint8_t flags = 0;
  std::string payload;
  bool trailer() const { return flags == 0x80; }
};

// Takes one complete frame off the front of `bytes`, if there is one.
inline std::optional<Frame> take_frame(std::string& bytes) {
  if (bytes.size() < 5) return std::nullopt;
  std::uint32_t n = 0;
  for (int i = 1; i < 5; ++i) n = (n << 8) | static_cast<std::uint8_t>(bytes[i]);
  if (bytes.size() < 5 + std::size_t(n)) return std::nullopt;
  Frame f{static_cast<std::uint8_t>(bytes[0]), bytes.substr(5, n)};
  bytes.erase(0, 5 + std::size_t(n));
  return f;
}

// A unary response body: its messages and its trailer.
struct Frames {
  std::vector<std::string> messages;
  std::string trailer;  // "grpc-status:0\r\n…"
  bool well_formed = true;  // whole frames, exactly one trailer, and it is last
};

inline Frames parse_frames(std::string body) {
  Frames out;
  while (!body.empty()) {
    std::optional<Frame> f = take_frame(body);
    if (!f || !out.trailer.empty()) return out.well_formed = false, out;
    if (f->trailer()) {
      out.trailer = std::move(f->payload);
    } else {
      out.messages.push_back(std::move(f->payload));
    }
  }
  out.well_formed = out.well_formed && !out.trailer.empty();
  return out;
}

}  // namespace filigree::test
