#pragma once
// Hierarchies forged the way loading cannot tell but the node graph can
// (hierarchy/node_graph.h): for tests of what happens when a session first
// needs it.

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "hierarchy/hierarchy.h"
#include "util/content_hash.h"

namespace filigree::test {

// A .fgh file's bytes with the header's payload checksum made right again
// (hierarchy_file.h: a 64-byte header, the XXH3 hash at byte 32): a file
// edited in place by a buggy or malicious producer. Shorter bytes are
// returned as they are.
inline std::string rehashed(std::string bytes) {
  constexpr std::size_t kHeader = 64, kHashAt = 32;
  if (bytes.size() < kHeader) return bytes;
  const std::uint64_t hash = hash_bytes(bytes.data() + kHeader, bytes.size() - kHeader);
  std::memcpy(bytes.data() + kHashAt, &hash, sizeof hash);
  return bytes;
}

// Re-triangulates the hole of the first node with a 4-vertex ring whose
// ring vertices are all removed later, across its other diagonal: still a
// triangulation of its ring (loading accepts it), but not the faces the
// later removals' fans were made of. Returns that node, or kNone if there
// is none.
inline NodeId flip_a_quad_diagonal(Hierarchy& h) {
  const std::vector<NodeId> node_of = vertex_nodes(h);
  for (NodeId k = 0; k < h.node_count(); ++k) {
    const auto ring = h.ring(k);
    if (ring.size() != 4 || std::any_of(ring.begin(), ring.end(), [&](Index u) { return node_of[u] == kNone; })) continue;
    RingCorners* made = &h.created_corners.edit()[h.first_created_face(k) - h.original_face_count()];
    const bool across_0_2 = std::count(made[0].begin(), made[0].end(), 0) && std::count(made[0].begin(), made[0].end(), 2);
    if (across_0_2) {
      made[0] = {1, 2, 3}, made[1] = {3, 0, 1};
    } else {
      made[0] = {0, 1, 2}, made[1] = {2, 3, 0};
    }
    return k;
  }
  return kNone;
}

}  // namespace filigree::test
