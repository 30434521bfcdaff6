// Hierarchy files (.fgh): read back from the data directory or a shared store,
// then the node graph a finite T derives from them (the checks loading leaves
// to it).

#include <exception>
#include <span>

#include "fuzz_input.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "hierarchy/node_graph.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const filigree::Hierarchy h = filigree::deserialize_hierarchy(std::span(reinterpret_cast<const char*>(data), size), "<fuzz>");
    const filigree::NodeGraph graph(h);
  } catch (const std::exception&) {
  }
  return 0;
}
