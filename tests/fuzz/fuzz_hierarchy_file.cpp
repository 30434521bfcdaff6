// Hierarchy files (.fgh) as a buggy or malicious producer would write them:
// read back from the data directory or a shared store, then the node graph a
// finite T derives from them (the checks loading leaves to it). The payload
// checksum is made right first, so that mutations reach the validation
// instead of stopping at the hash (which the unit tests cover).

#include <cstring>
#include <exception>
#include <span>
#include <string>

#include "fuzz_input.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "hierarchy/node_graph.h"
#include "util/content_hash.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::string bytes(reinterpret_cast<const char*>(data), size);
  constexpr std::size_t kHeader = 64, kHashAt = 32;  // hierarchy_file.h
  if (bytes.size() >= kHeader) {
    const std::uint64_t hash = filigree::hash_bytes(bytes.data() + kHeader, bytes.size() - kHeader);
    std::memcpy(bytes.data() + kHashAt, &hash, sizeof hash);
  }
  try {
    const filigree::Hierarchy h = filigree::deserialize_hierarchy(std::span<const char>(bytes), "<fuzz>");
    const filigree::NodeGraph graph(h);
  } catch (const std::exception&) {
  }
  return 0;
}
