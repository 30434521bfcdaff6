#pragma once
// The rig file: a Rig (rig.h) as a small versioned binary blob. A session
// record stores it, and `filigree preprocess` writes it next to X.fgh as X.rig.
//
// Layout, version 1, little-endian, no padding; u32/i32/u8 are integers,
// f32/f64 IEEE floats, str is a u32 byte length then that many bytes (UTF-8,
// no terminator), and "n × {…}" repeats the braces n times:
//   magic  "FLGRIG\0\0" (8 bytes)
//   u32    format version (1)
//   u32    joint count J (≤ 65535)
//   J × {  str name; i32 parent (−1 for a root);
//          f64 rest translation[3]; f64 rest rotation[4] (x y z w);
//          f64 rest scale[3]; f64 root_parent[16] (column-major) }
//   u32    binding count B
//   B × {  u32 joint; f64 inverse_bind[16] (column-major) }
//   u32    vertex count V
//   u32    offsets[V + 1]
//   u32    influence count I
//   u32    binding[I]
//   f32    weight[I]
//   f64    bind_positions[3·V] (x y z per vertex)
//   u32    clip count C
//   C × {  str name; u32 channel count H;
//          H × { u32 joint; u8 path (0 translation, 1 rotation, 2 scale);
//                u8 interpolation (0 step, 1 linear, 2 cubic spline);
//                u32 key count K; f32 times[K];
//                u32 value count N; f32 values[N] } }
// and nothing after. Doubles stay doubles (bit-exact round trips); times,
// values and weights are glTF's float32 already.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "skinning/rig.h"

namespace filigree {

inline constexpr std::uint32_t kRigFormatVersion = 1;

// The rig's bytes; deterministic: the same rig gives the same bytes. Throws
// RigError for a rig that validate_rig rejects, so nothing is written that
// could not be read back.
std::string serialize_rig(const Rig& rig);

// The rig in `bytes`. Never reads out of bounds and never allocates more than
// the bytes could hold; the result has passed validate_rig. Every failure
// (truncated, bad magic, unknown version, a count larger than the bytes left,
// trailing bytes, an invalid rig) throws RigError whose what() starts with
// name_for_errors and says what is wrong.
Rig deserialize_rig(std::string_view bytes, const std::string& name_for_errors = "<memory>");

// Writes to `path`.partial, then renames it over `path`: a crash never leaves
// half a file under the real name. Throws RigError (message starts with the
// path) if the rig is invalid or the file cannot be written.
void save_rig(const Rig& rig, const std::filesystem::path& path);

// deserialize_rig of the file's bytes, with the path as the name for errors;
// a file that cannot be read is a RigError too.
Rig load_rig(const std::filesystem::path& path);

}  // namespace filigree
