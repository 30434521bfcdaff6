#include "server/resident_memory.h"

#include <malloc.h>
#include <unistd.h>

#include <fstream>

namespace filigree::server {

std::size_t resident_bytes() {
  std::ifstream statm("/proc/self/statm");
  std::size_t total_pages = 0, resident_pages = 0;
  if (!(statm >> total_pages >> resident_pages)) return 0;
  return resident_pages * static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
}

void release_free_memory() { ::malloc_trim(0); }

void keep_large_buffers_out_of_the_heap() {
  constexpr int kThreshold = 256 * 1024;
  ::mallopt(M_MMAP_THRESHOLD, kThreshold);  // also stops the threshold from moving
  ::mallopt(M_TRIM_THRESHOLD, kThreshold);  // and return a heap's free top past this
}

}  // namespace filigree::server
