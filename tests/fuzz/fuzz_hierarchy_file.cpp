// Hierarchy files (.fgh): read back from the data directory or a shared store.

#include <exception>
#include <span>

#include "fuzz_input.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    (void)filigree::deserialize_hierarchy(std::span(reinterpret_cast<const char*>(data), size), "<fuzz>");
  } catch (const std::exception&) {
  }
  return 0;
}
