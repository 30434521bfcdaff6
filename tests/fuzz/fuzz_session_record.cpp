// Session records and journaled progress, as read back from the data
// directory or from Redis (which another replica wrote).

#include <exception>

#include "fuzz_input.h"
#include "server/session_record.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string bytes = filigree::fuzz::as_string(data, size);
  try {
    filigree::server::SessionRecord r = filigree::server::decode_session_record(bytes);
    filigree::server::apply_session_progress(bytes, r);
  } catch (const std::exception&) {
  }
  return 0;
}
