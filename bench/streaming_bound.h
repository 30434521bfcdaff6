#pragma once
// The memory bound of a pass over a frame: the time this machine takes to
// stream a given number of bytes (a plain copy, half read and half written),
// measured in the same run as the pass it bounds.

#include <cstddef>

namespace filigree::bench {

// Best of `repeats` timings, in ms, of copying bytes/2 bytes (so `bytes` are
// touched) on `threads` threads, each its own contiguous range; buffers are
// allocated and faulted in before timing.
double streaming_copy_ms(std::size_t bytes, int threads, int repeats = 7);

}  // namespace filigree::bench
