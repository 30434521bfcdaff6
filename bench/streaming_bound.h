#pragma once
// The memory bound of a pass over a frame: the time this machine takes to
// stream a given number of bytes (a plain copy, half read and half written),
// measured in the same run as the pass it bounds.

#include <cstddef>
#include <vector>

namespace filigree::bench {

// Two buffers of bytes/2 each, allocated and faulted in once, so that each
// timed copy is the copy alone (and can be interleaved with the pass it
// bounds: both then see the same machine).
class StreamingCopy {
 public:
  explicit StreamingCopy(std::size_t bytes);
  // Copies bytes/2 bytes (so `bytes` are touched) on `threads` threads, each
  // its own contiguous range; returns the time in ms.
  double run_ms(int threads);

 private:
  std::vector<char> src_, dst_;
  std::size_t runs_ = 0;
};

}  // namespace filigree::bench
