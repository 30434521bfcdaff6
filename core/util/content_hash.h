#pragma once
// A 64-bit content hash (XXH3) for identifying meshes and checking file payloads.

#include <cstddef>
#include <cstdint>
#include <string>

namespace filigree {

struct TriMesh;

// Streaming hash of byte ranges; same bytes in the same order → same value.
class ContentHasher {
 public:
  ContentHasher();
  ~ContentHasher();
  ContentHasher(const ContentHasher&) = delete;
  ContentHasher& operator=(const ContentHasher&) = delete;
  void update(const void* data, std::size_t size);
  std::uint64_t digest() const;

 private:
  void* state_;
};

std::uint64_t hash_bytes(const void* data, std::size_t size);

// Hash of a mesh's vertex count, face count, exact coordinates and indices.
std::uint64_t hash_mesh(const TriMesh& mesh);

// "0123456789abcdef"
std::string hash_to_hex(std::uint64_t hash);

}  // namespace filigree
