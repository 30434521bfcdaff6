#pragma once
// The process's resident memory, what --max-memory bounds: what a container
// limit or the OOM killer counts, allocator caches and gRPC's buffers
// included, rather than an estimate of our own structures.

#include <cstddef>

namespace filigree::server {

// Resident set size of this process in bytes (/proc/self/statm); 0 if it
// cannot be read (then no limit can be enforced, and callers let work in).
std::size_t resident_bytes();

// Returns freed heap pages to the OS (glibc malloc_trim), so that memory a
// dropped session held shows in resident_bytes() at once.
void release_free_memory();

}  // namespace filigree::server
