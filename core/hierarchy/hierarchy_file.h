#pragma once
// The hierarchy file (.fgh): a versioned binary blob that loads much faster
// than the hierarchy builds (DESIGN §2.1.6).
//
// Layout (little-endian): a 64-byte header — magic "FLGHIER\0", u32 format
// version, u32 header size, u64 mesh hash, u64 payload size, u64 XXH3 hash of
// the payload, u32 vertex count, u32 face count, u32 original face count,
// u32 node count, u32 section count, u32 reserved — then sections, each
// u32 tag, u32 element size, u64 element count, the elements, zero padding to
// 8 bytes. The sections are the arrays of a StoredHierarchy (hierarchy.h) in
// its order, then the build record; every element sits at a multiple of its
// alignment, so a loaded file is read in place.
//
// Version 3 (issue 10) stores only what cannot be derived, in float32 or
// 16-bit fixed point where the hierarchy allows it: ~119 bytes per vertex,
// against ~170 in version 2 (which also stored the faces each removal
// deleted and the dependency edges) and ~310 in version 1. Version 2 files
// are still read (converted on load: its float weights and barycentrics
// rounded to 16 bits, the offsets recomputed for them), since a persisted
// session names its hierarchy with no mesh to rebuild it from; version 1
// files are refused with a message to rebuild them.
//
// Loading maps the file read-only, checks the header, every size against the
// bytes present, the payload hash, then validates the mapped arrays
// (validate_hierarchy): a truncated, corrupt or forged file is an error,
// never a crash or an out-of-bounds read. The loaded hierarchy's arrays are
// then views of the mapping, not copies (issue 10: 1.25M vertices load in
// well under half the time), so the file stays mapped while the hierarchy
// lives. A file truncated *while* it is mapped would fault: writers replace
// files by renaming a finished one, as save_hierarchy and the server's
// cache do, never in place; a file replaced or deleted that way leaves the
// mapping intact.

#include <cstdint>
#include <filesystem>
#include <span>
#include <stdexcept>
#include <string>

namespace filigree {

struct Hierarchy;

inline constexpr std::uint32_t kHierarchyFormatVersion = 3;

// what() starts with the file name (or "<memory>") and says what is wrong.
struct HierarchyFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Writing is deterministic: the same hierarchy gives the same bytes.
void save_hierarchy(const Hierarchy& h, const std::filesystem::path& path);
std::string serialize_hierarchy(const Hierarchy& h);

// The arrays read in place from the mapped file (version 3).
Hierarchy load_hierarchy(const std::filesystem::path& path);
// The arrays copied out of `bytes`.
Hierarchy deserialize_hierarchy(std::span<const char> bytes, const std::string& name_for_errors = "<memory>");

// Header fields, read without loading the payload (for `inspect` and caches).
struct HierarchyFileInfo {
  std::uint32_t version = 0;
  std::uint64_t mesh_hash = 0;
  std::uint64_t file_size = 0;
  std::uint32_t vertex_count = 0, face_count = 0, original_face_count = 0, node_count = 0;
};
HierarchyFileInfo read_hierarchy_file_info(const std::filesystem::path& path);

}  // namespace filigree
