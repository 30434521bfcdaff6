#include "hierarchy/node_graph.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <string>
#include <thread>
#include <tuple>
#include <utility>

#include "hierarchy/hierarchy.h"
#include "util/parallel_for.h"

namespace filigree {
namespace {

[[noreturn]] void fail(const std::string& what) { throw HierarchyError("invalid hierarchy: " + what); }

std::string str(std::size_t v) { return std::to_string(v); }

// Faces [begin, end) in blocks of up to kBlock: their corners and creators
// (kNone for an original face), read in order.
constexpr std::size_t kBlock = 256;
struct FaceBlock {
  std::size_t size = 0;
  Triangle tri[kBlock];
  NodeId creator[kBlock];
};

template <class Fn>
void for_each_face_block(const Hierarchy& h, std::size_t begin, std::size_t end, Fn&& fn) {
  FaceBlock b;
  const std::size_t original = h.original_face_count();
  NodeId c = begin < original ? 0 : h.creator(static_cast<FaceId>(begin));
  for (std::size_t first = begin; first < end; first += kBlock) {
    b.size = std::min(kBlock, end - first);
    for (std::size_t i = 0; i < b.size; ++i) {
      const std::size_t f = first + i;
      if (f < original) {
        b.tri[i] = h.original_faces[f];
        b.creator[i] = kNone;
        continue;
      }
      while (f >= h.first_created_face(c) + h.ring_size(c) - 2) ++c;
      b.tri[i] = h.created_face(c, f - h.first_created_face(c));
      b.creator[i] = c;
    }
    fn(first, b);
  }
}

// The node that deletes a face: the first of its vertices to be removed
// (they were all present when it was made), kNone for a base face; and
// which corner that vertex is.
std::pair<NodeId, std::uint8_t> deleter(const std::vector<NodeId>& node_of, const Triangle& t) {
  const NodeId a = node_of[t[0]], b = node_of[t[1]], c = node_of[t[2]];
  const NodeId k = std::min({a, b, c});
  return {k, k == a ? 0 : k == b ? 1 : 2};
}

}  // namespace

NodeGraph::NodeGraph(const Hierarchy& h, std::size_t threads) : h_(&h), vertex_node_(filigree::vertex_nodes(h)) {
  const std::size_t nodes = h.node_count(), slots = h.ring_vertices.size(), faces = h.face_count();
  const std::vector<NodeId>& node_of = vertex_node_;
  // Every read below is scattered (a face's vertices, its deleter's ring and
  // slots): each pass requests what a face kAhead later needs, so that many
  // loads are in flight, and both cores take half the faces (1.25M
  // vertices: 1.0 s → 0.33–0.41 s).
  constexpr std::size_t kAhead = 32;
  const std::size_t parts =
      threads ? std::min(threads, std::max<std::size_t>(faces, 1))
              : (faces >= 100000 ? std::clamp<std::size_t>(std::thread::hardware_concurrency(), 1, 2) : 1);

  // Pass 1: each face's deleter, and its corner.
  std::vector<NodeId> face_deleter(faces);
  std::vector<std::uint8_t> face_corner(faces);
  parallel_ranges(faces, parts, [&](std::size_t begin, std::size_t end) {
    for_each_face_block(h, begin, end, [&](std::size_t first, const FaceBlock& b) {
      for (std::size_t i = 0; i < b.size; ++i) {
        if (i + kAhead < b.size)
          for (Index v : b.tri[i + kAhead]) __builtin_prefetch(&node_of[v]);
        std::tie(face_deleter[first + i], face_corner[first + i]) = deleter(node_of, b.tri[i]);
      }
    });
  });

  // Pass 2: each deleted face into its deleter's fan slot, the one that
  // starts at the face's next corner, with its creator (a child of the
  // deleter). A slot taken twice is a forged hierarchy, so slots are claimed
  // atomically.
  std::vector<std::array<Index, 2>> slot(slots, {kNone, kNone});  // face, creator
  std::atomic<std::size_t> deleted{0}, deleted_created{0};
  parallel_ranges(faces, parts, [&](std::size_t begin, std::size_t end) {
    std::size_t mine = 0, mine_created = 0;
    for_each_face_block(h, begin, end, [&](std::size_t first, const FaceBlock& b) {
      const NodeId* k_of = face_deleter.data() + first;
      for (std::size_t i = 0; i < b.size; ++i) {
        if (i + kAhead < b.size && k_of[i + kAhead] != kNone) __builtin_prefetch(&h.ring_offsets[k_of[i + kAhead]]);
        if (i + kAhead / 2 < b.size && k_of[i + kAhead / 2] != kNone) {
          const Index off = h.ring_offsets[k_of[i + kAhead / 2]];
          __builtin_prefetch(&h.ring_vertices[off]);
          __builtin_prefetch(&slot[off], 1);
        }
        const NodeId k = k_of[i];
        if (k == kNone) continue;  // a base face
        const FaceId f = static_cast<FaceId>(first + i);
        const Triangle& t = b.tri[i];
        const int at = face_corner[first + i];
        const Index next = t[(at + 1) % 3], after = t[(at + 2) % 3];
        const auto ring = h.ring(k);
        const std::size_t s = static_cast<std::size_t>(std::find(ring.begin(), ring.end(), next) - ring.begin());
        if (s >= h.fan_size(k) || ring[s + 1 == ring.size() ? 0 : s + 1] != after)
          fail("node " + str(k) + " removes the vertex of face " + str(f) + ", which is not in its fan");
        if (b.creator[i] != kNone && b.creator[i] >= k) fail("node " + str(k) + " deletes face " + str(f) + " before it exists");
        Index expected = kNone;
        if (!std::atomic_ref<Index>(slot[h.ring_offsets[k] + s][0]).compare_exchange_strong(expected, f))
          fail("node " + str(k) + " deletes two faces in fan slot " + str(s));
        slot[h.ring_offsets[k] + s][1] = b.creator[i];
        ++mine;
        mine_created += b.creator[i] != kNone;
      }
    });
    deleted += mine;
    deleted_created += mine_created;
  });

  std::size_t fans = 0;
  for (NodeId k = 0; k < nodes; ++k) fans += h.fan_size(k);
  if (deleted != fans) {
    for (NodeId k = 0; k < nodes; ++k)
      for (std::size_t i = 0; i < h.fan_size(k); ++i)
        if (slot[h.ring_offsets[k] + i][0] == kNone) fail("node " + str(k) + " has no face in fan slot " + str(i));
  }
  removed_faces_.resize(slots);
  for (std::size_t j = 0; j < slots; ++j) removed_faces_[j] = slot[j][0];

  // Children: the creators of the deleted faces, ascending, once each.
  child_offsets_.assign(1, 0);
  child_offsets_.reserve(nodes + 1);
  children_.reserve(deleted_created);  // at most one edge per created face deleted
  for (NodeId k = 0; k < nodes; ++k) {
    const std::size_t first = children_.size();
    for (std::size_t j = h.ring_offsets[k]; j < h.ring_offsets[k + 1]; ++j)
      if (slot[j][1] != kNone) children_.push_back(slot[j][1]);
    std::sort(children_.begin() + static_cast<std::ptrdiff_t>(first), children_.end());
    children_.erase(std::unique(children_.begin() + static_cast<std::ptrdiff_t>(first), children_.end()), children_.end());
    child_offsets_.push_back(static_cast<Index>(children_.size()));
  }
  children_.shrink_to_fit();

  // Parents: the inverse, by a counting sort that keeps them ascending. Its
  // counters and slots are scattered: each is prefetched kAhead edges early
  // (1.25M vertices: 45 → 30 ms).
  const std::size_t edges = children_.size();
  parent_offsets_.assign(nodes + 1, 0);
  for (std::size_t i = 0; i < edges; ++i) {
    if (i + kAhead < edges) __builtin_prefetch(&parent_offsets_[children_[i + kAhead] + 1], 1);
    ++parent_offsets_[children_[i] + 1];
  }
  for (std::size_t k = 0; k < nodes; ++k) parent_offsets_[k + 1] += parent_offsets_[k];
  parents_.resize(edges);
  std::vector<Index> fill(parent_offsets_.begin(), parent_offsets_.end() - 1);
  std::size_t i = 0;
  for (std::size_t k = 0; k < nodes; ++k) {
    for (; i < child_offsets_[k + 1]; ++i) {
      if (i + 2 * kAhead < edges) __builtin_prefetch(&fill[children_[i + 2 * kAhead]], 1);
      if (i + kAhead < edges) __builtin_prefetch(&parents_[fill[children_[i + kAhead]]], 1);
      parents_[fill[children_[i]]++] = static_cast<NodeId>(k);
    }
  }
}

std::size_t NodeGraph::memory_bytes() const {
  return vertex_node_.capacity() * sizeof(NodeId) + removed_faces_.capacity() * sizeof(FaceId) +
         (child_offsets_.capacity() + parent_offsets_.capacity()) * sizeof(Index) + (children_.capacity() + parents_.capacity()) * sizeof(NodeId);
}

}  // namespace filigree
