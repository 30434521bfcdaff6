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

// Fixes glibc's mmap threshold at 256 KiB: buffers of that size or more (a
// mesh being parsed, a frame, a chunk's Draco scratch) get pages of their own
// that go back to the OS when freed. glibc otherwise raises the threshold after
// such a free, and later big buffers then come from heaps that freed memory
// cannot leave: on the 435k dragon, each further session grew the server by
// 127 B/vertex instead of 81. Call once, before any thread starts.
void keep_large_buffers_out_of_the_heap();

}  // namespace filigree::server
