// Rig files (FLGRIG): next to a hierarchy, and inside every session record.

#include <exception>
#include <string_view>

#include "fuzz_input.h"
#include "skinning/rig_file.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    (void)filigree::deserialize_rig(std::string_view(reinterpret_cast<const char*>(data), size), "<fuzz>");
  } catch (const std::exception&) {
  }
  return 0;
}
