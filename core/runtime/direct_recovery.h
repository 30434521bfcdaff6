#pragma once
// Direct recovery of the cut vertices (thesis §3.4, eq. 3.10): each node's
// vertex is put back at its stored offset in the frame of its ring (the frame
// of geometry/ring_frame.h), parents before children.
//
// The hierarchy is laid out once for the traversal (this object, immutable and
// shared by every deformer of a mesh). Nodes go tile by tile — runs of
// kTileVertices vertices along a Morton curve — and within a tile level by
// level (a level only reads levels above it), so ring reads and output
// writes stay in a cache-sized window rather than every level sweeping the
// whole mesh; threads take contiguous runs of the curve, a node whose parent
// lies in another thread's run waiting for a later phase. Nodes of one
// tile and level form blocks of kLanes; each block stores its rings padded to
// its largest ring, as structure of arrays (ring slot × lane), so that a
// block's frames are computed lane-parallel with SIMD and no integer
// division. Ring indices are renumbered into the traversal's own order (base
// vertices, then nodes as processed), so ring reads mostly hit recent writes;
// the kernel prefetches a few blocks ahead the ring rows that do not (coarse
// nodes, jumps of the Morton curve) and the output lines, which are scattered
// into the caller's order. Threads meet between phases at a spinning barrier.
//
// Precision: positions, weights and offsets are float32, relative to an
// origin near the pose (the rest base centroid, moved in whole steps of the
// mesh's size when the pose travels), so the error does not grow with the
// distance from the coordinate origin: ~1e-7 of the bounding-box diagonal
// against the double-precision reference (tests/test_direct_recovery.cpp;
// issue 10 allows 1e-5). Each vertex also carries the float error of
// recovering the rest pose, added back on output: the rest pose gives the rest
// mesh exactly, and parts of the mesh the pose leaves alone stay exactly at
// rest (no float noise for the cut to score or for frames to send).
// Results are returned in double.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct Hierarchy;

// One deformer's scratch for recovery: positions in traversal order.
struct RecoveryWorkspace {
  std::vector<float> xyzw;  // 4 floats per traversal slot (16-byte aligned rows)
  std::array<double, 3> origin{};  // what the floats are relative to
};

class DirectRecovery {
 public:
  static constexpr std::size_t kLanes = 8;

  // `partitions`: how many threads the layout can use at once; 0 picks one
  // per kNodesPerThread nodes, at most the machine's cores (results never
  // depend on it, only speed). `kernel`: one of kernels(), empty for the
  // fastest; throws std::invalid_argument for a name not in kernels().
  explicit DirectRecovery(const Hierarchy& h, std::size_t partitions = 0, std::string_view kernel = {});

  // The compiled copies of the kernel this processor runs ("baseline",
  // "avx2", "avx512"), the newest instruction set last (the default).
  // Their results differ only in float rounding, each within the precision
  // promised above.
  static std::vector<std::string_view> kernels();
  std::string_view kernel() const;

  // Recovers every node from the base positions `base` (base order) and
  // writes every vertex's position, base vertices included, into `out`
  // (original order; out.size() must be the vertex count), once. `ws` is the
  // caller's scratch. Every node is computed, whatever a cut holds: a
  // branch-free kernel stays SIMD, and callers overwrite what they optimise.
  // Uses at most `threads` threads; the result does not depend on how many.
  // Threads beyond partitions() do not help; the layout has one partition
  // per kNodesPerThread nodes, at most kMaxPartitions.
  void recover(std::span<const Vec3> base, RecoveryWorkspace& ws, std::span<Vec3> out, int threads) const;

  // Measured on this 2-core machine, one thread against two over two
  // partitions (medians of 200 alternating frames): 9.6k nodes 2.55×,
  // 25k 1.44×, 48k 0.95×, 102k 0.69×, 148k 0.66×; and one thread over a
  // two-partition layout costs what it does over one (148k: 1.01×).
  static constexpr std::size_t kNodesPerThread = 50000;
  static constexpr std::size_t kMaxPartitions = 8;
  // Vertices per tile of the traversal: a tile's positions (16 B each) and
  // results (24 B), 640 KiB, stay within a core's L2 (1 MiB on Zen 4) while
  // it runs. Blocks never span two tiles' levels, so larger tiles pad fewer
  // lanes: at 1.25M vertices 16384 has 5% fewer blocks than 4096 (5% fewer
  // bytes a frame) and builds its layout in 1.4 s instead of 2.0.
  static constexpr std::size_t kTileVertices = 16384;

  std::size_t vertex_count() const { return slot_of_vertex_.size(); }
  // Floats a RecoveryWorkspace holds during recover().
  std::size_t scratch_floats() const { return 4 * (base_count_ + vertex_of_slot_.size()); }
  std::size_t node_count() const { return node_count_; }
  std::size_t partitions() const { return partitions_; }
  std::size_t blocks() const { return segment_blocks_.back(); }
  // Phases of the threaded traversal: a node with a parent in another
  // partition runs in a later phase than that parent (a barrier apart).
  std::size_t phases() const { return phases_; }
  // Blocks of the busiest partition summed over phases: the threaded run's
  // critical path, against blocks() on one thread.
  std::size_t critical_blocks() const;
  // Bytes one recover() must move at least: the layout read once, every
  // traversal slot written once, the output written once (ring reads counted
  // as cache hits). The benchmark's streaming bound.
  std::size_t bytes_per_frame() const;
  // Heap bytes of this layout (shared by every deformer of the mesh).
  std::size_t memory_bytes() const;

 private:
  std::array<double, 3> origin_for(std::span<const Vec3> base) const;
  // Throws std::logic_error unless every position a block reads is a base
  // vertex's, or written by a block of an earlier phase or earlier in its
  // own partition and phase: what threads running partitions side by side
  // rely on. Checked once, when the layout is built.
  void check_schedule() const;

  std::size_t kernel_ = 0;  // index into kernels()
  std::size_t base_count_ = 0, node_count_ = 0;
  std::vector<Index> base_vertices_;       // base order → original id
  std::vector<Index> slot_of_vertex_;      // original id → traversal slot
  std::vector<Index> vertex_of_slot_;      // traversal slot − base_count_ → original id, kNone for padding lanes
  std::size_t partitions_ = 1, phases_ = 1;
  // Segment phase·partitions_ + partition is blocks [segment_blocks_[s], segment_blocks_[s+1]).
  std::vector<std::uint32_t> segment_blocks_;
  std::vector<std::uint32_t> block_ring_;       // block b's ring slots start at block_ring_[b]·kLanes; size blocks+1
  std::vector<std::uint32_t> ring_slot_;        // [ring slot][lane]: 4 × the ring vertex's traversal slot
  std::vector<float> ring_weight_;              // [ring slot][lane]: weight (0 on padding)
  std::vector<float> offset_;                   // [block][xyz][lane]: the node's local offset
  std::vector<std::uint8_t> lane_ring_;         // [block][lane]: ring size, | kOpenRing for open rings
  std::array<double, 3> rest_origin_{};         // centroid of the rest base
  double origin_step_ = 1.0;                    // the mesh's bounding-box diagonal
  std::vector<float> rest_error_;               // [block][xyz][lane]: rest − float recovery of the rest pose
};

}  // namespace filigree
