// Hierarchy files (.fgh) as a buggy or malicious producer would write them:
// read back from the data directory or a shared store, then the node graph a
// finite T derives from them (the checks loading leaves to it). The payload
// checksum is made right first, so that mutations reach the validation
// instead of stopping at the hash (which the unit tests cover).

#include <exception>
#include <span>
#include <string>

#include "fuzz_input.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "hierarchy/node_graph.h"
#include "tests/support/forged_hierarchy.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string bytes = filigree::test::rehashed(std::string(reinterpret_cast<const char*>(data), size));
  try {
    const filigree::Hierarchy h = filigree::deserialize_hierarchy(std::span<const char>(bytes), "<fuzz>");
    const filigree::NodeGraph graph(h);
  } catch (const std::exception&) {
  }
  return 0;
}
