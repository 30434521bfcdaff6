#include "util/content_hash.h"

#include <cstdio>

#include <xxhash.h>

#include "mesh/tri_mesh.h"

namespace filigree {

ContentHasher::ContentHasher() : state_(XXH3_createState()) { XXH3_64bits_reset(static_cast<XXH3_state_t*>(state_)); }
ContentHasher::~ContentHasher() { XXH3_freeState(static_cast<XXH3_state_t*>(state_)); }

void ContentHasher::update(const void* data, std::size_t size) {
  XXH3_64bits_update(static_cast<XXH3_state_t*>(state_), data, size);
}

std::uint64_t ContentHasher::digest() const { return XXH3_64bits_digest(static_cast<XXH3_state_t*>(state_)); }

std::uint64_t hash_bytes(const void* data, std::size_t size) { return XXH3_64bits(data, size); }

std::uint64_t hash_mesh(const TriMesh& mesh) {
  ContentHasher h;
  const std::uint64_t counts[2] = {mesh.positions.size(), mesh.faces.size()};
  h.update(counts, sizeof counts);
  h.update(mesh.positions.data(), mesh.positions.size() * sizeof(Vec3));
  h.update(mesh.faces.data(), mesh.faces.size() * sizeof(Triangle));
  return h.digest();
}

std::string hash_to_hex(std::uint64_t hash) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(hash));
  return buf;
}

}  // namespace filigree
