#pragma once
// What every fuzz target shares: its input as a string, and the one kind of
// outcome a parser may have besides success (an exception with a message).
// Anything else — a crash, a sanitizer report, a hang, an allocation past
// libFuzzer's limit — is a bug the target exists to find.

#include <cstddef>
#include <cstdint>
#include <string>

namespace filigree::fuzz {

inline std::string as_string(const std::uint8_t* data, std::size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

}  // namespace filigree::fuzz
