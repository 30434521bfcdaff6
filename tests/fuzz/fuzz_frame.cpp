// Frames as a client receives them: protobuf bytes of a v1::Frame, decoded
// (Draco deltas, chunk runs, keyframes) onto a rest mesh of the frame's own
// vertex count, as a client whose mesh matches would. A second input in the
// same decoder exercises sparse frames against the first, or, when the first
// starts a level of detail (Frame.level: a Draco mesh of original ids), the
// level's frames.

#include <algorithm>
#include <exception>
#include <vector>

#include "filigree/frame_decoder.h"
#include "filigree/v1/filigree.pb.h"
#include "fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Two frames: the first byte says where the first one ends.
  if (size < 1) return 0;
  const std::size_t split = std::min<std::size_t>(size - 1, std::size_t{data[0]} * 16);
  filigree::v1::Frame first, second;
  if (!first.ParseFromArray(data + 1, static_cast<int>(split))) return 0;
  const bool two = second.ParseFromArray(data + 1 + split, static_cast<int>(size - 1 - split));
  // A client's mesh has as many vertices as its frames say (bounded: the
  // decoder's allocation is the client's, not the input's, to choose).
  if (first.vertex_count() > 1u << 16) return 0;
  try {
    filigree::FrameDecoder decoder(std::vector<float>(3 * first.vertex_count(), 0.5f), 1);
    if (first.has_level())
      (void)decoder.set_level(first.level());
    else
      (void)decoder.decode(first);
    if (two) (void)decoder.decode(second);
  } catch (const std::exception&) {
    // ClientError (DATA_LOSS): what a client reports for a frame it cannot decode.
  }
  return 0;
}
