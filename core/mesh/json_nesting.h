#pragma once
// A bound on how deeply a JSON text nests arrays and objects, checked by one
// linear scan before any recursive parser sees the text: tinygltf 2.7
// converts JSON to its Value type recursively, and ~15,000 nested arrays
// (30 KB) overflow a thread's stack.

#include <cstddef>
#include <string_view>

namespace filigree {

// The deepest nesting any glTF we read may have. Real files stay under 20
// (extras and extensions included); 128 leaves room and keeps a recursive
// parser's stack use in the tens of kilobytes.
inline constexpr std::size_t kMaxJsonNesting = 128;

// The deepest nesting of `[` and `{` in `json`, counted outside strings
// (escapes honoured). Stops counting, and returns max_depth + 1, as soon as
// the text goes deeper than `max_depth`. Malformed text is not an error here:
// the parser that follows reports it.
std::size_t json_nesting(std::string_view json, std::size_t max_depth);

}  // namespace filigree
