#pragma once
// Process memory statistics (Linux /proc), for summaries and benchmarks.

#include <cstddef>

namespace filigree {

// Peak resident set size of this process in bytes (VmHWM); 0 if unknown.
std::size_t peak_memory_bytes();

// Resets the peak so that the next peak_memory_bytes() measures from now
// (Linux ≥ 4.0 clear_refs); returns false where unsupported.
bool reset_peak_memory();

}  // namespace filigree
