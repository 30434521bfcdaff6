#include "runtime/direct_recovery.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <thread>

#include "hierarchy/hierarchy.h"
#include "mesh/vertex_order.h"
#include "util/cpu_features.h"
#include "util/helper_team.h"
#include "util/parallel_for.h"
#include "util/spin_barrier.h"

namespace filigree {
namespace {

constexpr std::size_t W = DirectRecovery::kLanes;
// The simplifier never removes a vertex of valence > 32; a hierarchy with a
// larger ring is refused when the layout is built (kernel scratch is fixed).
constexpr std::size_t kMaxRing = 64;
constexpr std::uint8_t kOpenRing = 0x80;

struct Block {
  const std::uint32_t* slot;  // [ring slot][lane]: 4 × the traversal slot (a float index)
  const float* weight;        // [ring slot][lane]
  std::size_t ring;           // ring slots (the block's largest ring)
  const float* offset;        // [xyz][lane]
  const std::uint8_t* meta;   // [lane]: ring size | kOpenRing
  const float* error;         // [xyz][lane]: rest error (see the header)
  const Index* vertex;        // [lane]: original id, kNone for padding lanes
  std::size_t out;            // traversal slot of lane 0
};

// Where results go besides the workspace: the caller's buffer, in its order.
struct Output {
  double* xyz;                // 3 doubles per original vertex
  double ox, oy, oz;          // the workspace's origin
};
constexpr Index kPaddingLane = kNone;  // vertex_of_slot_ of a padding lane

// Eight float lanes (GCC vector extensions): one lane per node of a block.
// Compiled for AVX2 each is one register; for the baseline, two SSE ones.
using F8 [[gnu::vector_size(32)]] = float;
using I8 [[gnu::vector_size(32)]] = std::int32_t;
using U8 [[gnu::vector_size(8)]] = std::uint8_t;
using F4 [[gnu::vector_size(16)]] = float;
using D8 [[gnu::vector_size(64)]] = double;
static_assert(W == 8, "the kernel's vectors hold one block");

[[gnu::always_inline]] inline F8 splat(float x) { return F8{} + x; }
[[gnu::always_inline]] inline F8 load8(const float* p) {
  F8 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline void store8(float* p, F8 v) { std::memcpy(p, &v, sizeof v); }
// Per lane; with -fno-math-errno (set for this file) it becomes one vsqrtps.
[[gnu::always_inline]] inline F8 sqrt8(F8 v) {
  F8 r;
  for (std::size_t l = 0; l < W; ++l) r[l] = __builtin_sqrtf(v[l]);
  return r;
}
[[gnu::always_inline]] inline F8 select(I8 mask, F8 a, F8 b) { return mask ? a : b; }

// One block of W nodes, lane-parallel: the frame of geometry/ring_frame.cpp
// written out (centre, mean radius, vector-area normal, tangent towards
// ring[0]) and eq. 3.10. Padding ring slots repeat ring[0] with weight 0, so
// the edge from a ring's last vertex to the first padding slot is the
// closing edge and padding–padding edges vanish (a × a = 0); masks drop the
// padding from the radius and the closing edge of open rings.
[[gnu::always_inline]] inline void recover_block(const Block& b, float* __restrict p, const Output& o) {
  F8 ax[kMaxRing], ay[kMaxRing], az[kMaxRing];
  F8 cx{}, cy{}, cz{};
  std::size_t i = 0;
  do {  // a block has at least one ring slot (ring[0] is read below)
    // Gather eight xyzw rows and transpose them to x, y, z lanes: pairs of
    // rows per register, then in-register shuffles (fewer instructions than
    // inserting 24 scalars).
    const std::uint32_t* slot = b.slot + i * W;
    F4 r[W];
    for (std::size_t l = 0; l < W; ++l) std::memcpy(&r[l], p + slot[l], sizeof(F4));
    const F8 a0 = __builtin_shufflevector(r[0], r[4], 0, 1, 2, 3, 4, 5, 6, 7);
    const F8 a1 = __builtin_shufflevector(r[1], r[5], 0, 1, 2, 3, 4, 5, 6, 7);
    const F8 a2 = __builtin_shufflevector(r[2], r[6], 0, 1, 2, 3, 4, 5, 6, 7);
    const F8 a3 = __builtin_shufflevector(r[3], r[7], 0, 1, 2, 3, 4, 5, 6, 7);
    const F8 t0 = __builtin_shufflevector(a0, a1, 0, 8, 1, 9, 4, 12, 5, 13);    // x0 x1 y0 y1 | x4 x5 y4 y5
    const F8 t1 = __builtin_shufflevector(a2, a3, 0, 8, 1, 9, 4, 12, 5, 13);    // x2 x3 y2 y3 | x6 x7 y6 y7
    const F8 t2 = __builtin_shufflevector(a0, a1, 2, 10, 3, 11, 6, 14, 7, 15);  // z0 z1 w0 w1 | z4 z5 w4 w5
    const F8 t3 = __builtin_shufflevector(a2, a3, 2, 10, 3, 11, 6, 14, 7, 15);
    const F8 x = __builtin_shufflevector(t0, t1, 0, 1, 8, 9, 4, 5, 12, 13);
    const F8 y = __builtin_shufflevector(t0, t1, 2, 3, 10, 11, 6, 7, 14, 15);
    const F8 z = __builtin_shufflevector(t2, t3, 0, 1, 8, 9, 4, 5, 12, 13);
    const F8 w = load8(b.weight + i * W);
    ax[i] = x, ay[i] = y, az[i] = z;
    cx += w * x, cy += w * y, cz += w * z;
  } while (++i < b.ring);
  U8 meta;
  std::memcpy(&meta, b.meta, sizeof meta);
  const F8 size = __builtin_convertvector(__builtin_convertvector(meta & 0x7f, I8), F8);
  const F8 edges = size - __builtin_convertvector(__builtin_convertvector(meta >> 7, I8), F8);  // open rings lose the closing edge
  // The ring relative to the centre, one vertex ahead of the edge loop (the
  // last edge closes on ring[0]): computed on the fly, not stored back.
  const F8 x0 = ax[0] - cx, y0 = ay[0] - cy, z0 = az[0] - cz;
  F8 nx{}, ny{}, nz{}, radius{};
  const F8 zero{}, one = splat(1.0f);
  F8 xi = x0, yi = y0, zi = z0, fi{};
  for (i = 0; i < b.ring; ++i, fi += one) {
    const bool last = i + 1 == b.ring;
    const F8 xj = last ? x0 : ax[i + 1] - cx, yj = last ? y0 : ay[i + 1] - cy, zj = last ? z0 : az[i + 1] - cz;
    radius += select(fi < size, sqrt8(xi * xi + yi * yi + zi * zi), zero);
    const F8 e = select(fi < edges, one, zero);
    nx += e * (yi * zj - zi * yj);
    ny += e * (zi * xj - xi * zj);
    nz += e * (xi * yj - yi * xj);
    xi = xj, yi = yj, zi = zj;
  }
  F8 s = radius / size;
  s = select(s > 1e-30f, s, one);  // a degenerate ring keeps scale 1, as ring_frame does
  const F8 nn = sqrt8(nx * nx + ny * ny + nz * nz);
  const I8 has_normal = nn > 1e-30f;
  const F8 inv_n = select(has_normal, one / nn, zero);
  const F8 n0 = nx * inv_n, n1 = ny * inv_n, n2 = select(has_normal, nz * inv_n, one);
  // Tangent: ring[0]'s direction in the tangent plane; when ring[0] lies on
  // the normal axis, X or Y projected instead (deterministic, as ring_frame).
  const F8 d0 = n0 * x0 + n1 * y0 + n2 * z0;
  F8 t0 = x0 - n0 * d0, t1 = y0 - n1 * d0, t2 = z0 - n2 * d0;
  const F8 tiny = 1e-6f * s;
  const I8 on_axis = t0 * t0 + t1 * t1 + t2 * t2 <= tiny * tiny;
  const F8 f0 = select(n0 < 0.9f && n0 > -0.9f, one, zero), f1 = one - f0;
  const F8 df = n0 * f0 + n1 * f1;
  t0 = select(on_axis, f0 - n0 * df, t0);
  t1 = select(on_axis, f1 - n1 * df, t1);
  t2 = select(on_axis, zero - n2 * df, t2);
  const F8 inv_t = one / sqrt8(t0 * t0 + t1 * t1 + t2 * t2);
  t0 *= inv_t, t1 *= inv_t, t2 *= inv_t;
  const F8 b0 = n1 * t2 - n2 * t1, b1 = n2 * t0 - n0 * t2, b2 = n0 * t1 - n1 * t0;
  const F8 o0 = load8(b.offset) * s, o1 = load8(b.offset + W) * s, o2 = load8(b.offset + 2 * W) * s;
  const F8 px = cx + t0 * o0 + b0 * o1 + n0 * o2;
  const F8 py = cy + t1 * o0 + b1 * o1 + n1 * o2;
  const F8 pz = cz + t2 * o0 + b2 * o1 + n2 * o2;
  // The workspace rows of the eight lanes are consecutive: transpose back to
  // xyz0 rows and store them whole.
  const F8 zero8{};
  const F8 u0 = __builtin_shufflevector(px, py, 0, 8, 1, 9, 4, 12, 5, 13);      // x0 y0 x1 y1 | x4 y4 x5 y5
  const F8 u1 = __builtin_shufflevector(px, py, 2, 10, 3, 11, 6, 14, 7, 15);    // x2 y2 x3 y3 | x6 y6 x7 y7
  const F8 u2 = __builtin_shufflevector(pz, zero8, 0, 8, 1, 9, 4, 12, 5, 13);   // z0 0 z1 0 | z4 0 z5 0
  const F8 u3 = __builtin_shufflevector(pz, zero8, 2, 10, 3, 11, 6, 14, 7, 15);
  const F8 r04 = __builtin_shufflevector(u0, u2, 0, 1, 8, 9, 4, 5, 12, 13);     // row 0 | row 4
  const F8 r15 = __builtin_shufflevector(u0, u2, 2, 3, 10, 11, 6, 7, 14, 15);
  const F8 r26 = __builtin_shufflevector(u1, u3, 0, 1, 8, 9, 4, 5, 12, 13);
  const F8 r37 = __builtin_shufflevector(u1, u3, 2, 3, 10, 11, 6, 7, 14, 15);
  // Each row pair stored from its register: as one array, GCC staged the rows
  // on the stack and copied them with 64-byte loads that straddle two 32-byte
  // stores (no store forwarding: a stall per block).
  store8(p + 4 * b.out, __builtin_shufflevector(r04, r15, 0, 1, 2, 3, 8, 9, 10, 11));
  store8(p + 4 * b.out + W, __builtin_shufflevector(r26, r37, 0, 1, 2, 3, 8, 9, 10, 11));
  store8(p + 4 * b.out + 2 * W, __builtin_shufflevector(r04, r15, 4, 5, 6, 7, 12, 13, 14, 15));
  store8(p + 4 * b.out + 3 * W, __builtin_shufflevector(r26, r37, 4, 5, 6, 7, 12, 13, 14, 15));

  // The caller's doubles: origin + float result + the rest error. Written
  // once, straight into the caller's order: a scattered store does not stall
  // the way a scattered load in a later pass would.
  // (Converted eight lanes at once: as two halves of four, GCC converted
  // two at a time through the stack.)
  const F8 ex = load8(b.error), ey = load8(b.error + W), ez = load8(b.error + 2 * W);
  const D8 dx = __builtin_convertvector(px, D8) + o.ox + __builtin_convertvector(ex, D8);
  const D8 dy = __builtin_convertvector(py, D8) + o.oy + __builtin_convertvector(ey, D8);
  const D8 dz = __builtin_convertvector(pz, D8) + o.oz + __builtin_convertvector(ez, D8);
  for (std::size_t l = 0; l < W; ++l) {
    if (b.vertex[l] == kPaddingLane) continue;
    double* d = o.xyz + 3 * static_cast<std::size_t>(b.vertex[l]);
    d[0] = dx[l], d[1] = dy[l], d[2] = dz[l];
  }
}

// How far ahead the output lines are prefetched, in blocks: far enough to
// hide a miss, near enough that the lines are still cached when written.
constexpr std::size_t kPrefetchBlocks = 4;
constexpr std::size_t kRingPrefetchBlocks = 2;  // ring reads come sooner: they are loads

struct Layout {
  const std::uint32_t* block_ring;
  const std::uint32_t* ring_slot;
  const float* ring_weight;
  const float* offset;
  const std::uint8_t* lane_ring;
  const float* rest_error;
  const Index* vertex_of_slot;
  std::size_t base;
};

[[gnu::always_inline]] inline void recover_blocks(const Layout& t, std::size_t first, std::size_t end, float* p, const Output& out) {
  const Output o = out;  // a local copy: stores through o.xyz cannot alias it
  for (std::size_t k = first; k < end; ++k) {
    const std::size_t r = t.block_ring[k] * W;
    const Block b{t.ring_slot + r,         t.ring_weight + r,       t.block_ring[k + 1] - t.block_ring[k],
                  t.offset + 3 * W * k,    t.lane_ring + W * k,     t.rest_error + 3 * W * k,
                  t.vertex_of_slot + W * k, t.base + W * k};
    if (k + kPrefetchBlocks < end) {
      // The output is scattered (the caller's order), and a store that misses
      // the cache holds up the stores behind it: ask for a later block's
      // output lines now (measured on 1.25M vertices: a frame ~25% faster).
      // Padding lanes use lane 0's address (never padding).
      const Index* ahead = t.vertex_of_slot + W * (k + kPrefetchBlocks);
      for (std::size_t l = 0; l < W; ++l) {
        const Index v = ahead[l] == kPaddingLane ? ahead[0] : ahead[l];
        const double* d = o.xyz + 3 * static_cast<std::size_t>(v);
        __builtin_prefetch(d, 1, 3);      // a vertex's 24 bytes may span two lines
        __builtin_prefetch(d + 2, 1, 3);
      }
    }
    if (k + kRingPrefetchBlocks < end) {
      // Ring reads of coarse nodes reach far back in the traversal, out of
      // cache: fetch a later block's ring rows now (~15% a frame at 1.25M).
      const std::size_t ahead = k + kRingPrefetchBlocks;
      const std::uint32_t* slot = t.ring_slot + t.block_ring[ahead] * W;
      // A ring slot's W rows at a time, unrolled: the loop's own counting
      // was most of these instructions.
      for (std::size_t i = t.block_ring[ahead]; i < t.block_ring[ahead + 1]; ++i, slot += W)
        for (std::size_t l = 0; l < W; ++l) __builtin_prefetch(p + slot[l], 0, 3);
    }
    recover_block(b, p, o);
  }
}

// The same code compiled for newer instruction sets where the processor has
// them, chosen at run time so one binary runs everywhere. AVX-512 (VL forms
// of the same 8-lane vectors, mask registers for the selects, 8 doubles in
// one register for the output, FMA contracted) is ~10% faster than AVX2 on
// the 1.25M mesh (Zen 4, 1 and 2 threads); AVX2 with FMA alone was not.
// On Zen 5 the AVX2 copy runs at 0.94–0.95 of the AVX-512 one
// (`filigree_bench_runtime --kernels`, 2026-11-26): the order is Zen 4's.
// Copies differ in float rounding (FMA), each within the header's bound.
using BlocksFn = void (*)(const Layout&, std::size_t, std::size_t, float*, const Output&);
struct KernelCopy {
  std::string_view name;
  BlocksFn run;
};

void recover_blocks_baseline(const Layout& t, std::size_t first, std::size_t end, float* p, const Output& o) {
  recover_blocks(t, first, end, p, o);
}
#if FILIGREE_X86_TARGETS
[[gnu::target("avx2")]] void recover_blocks_avx2(const Layout& t, std::size_t first, std::size_t end, float* p, const Output& o) {
  recover_blocks(t, first, end, p, o);
}
[[gnu::target("avx512f,avx512vl,avx512dq,avx512bw,fma")]] void recover_blocks_avx512(const Layout& t, std::size_t first, std::size_t end,
                                                                                    float* p, const Output& o) {
  recover_blocks(t, first, end, p, o);
}
#endif

std::vector<KernelCopy> runnable_kernels() {
  std::vector<KernelCopy> out = {{"baseline", recover_blocks_baseline}};
#if FILIGREE_X86_TARGETS
  if (cpu_has_avx2()) out.push_back({"avx2", recover_blocks_avx2});
  if (cpu_has_avx512()) out.push_back({"avx512", recover_blocks_avx512});
#endif
  return out;
}

// Found on first use, so that no static initialiser can see it unset.
const std::vector<KernelCopy>& kernel_copies() {
  static const std::vector<KernelCopy> copies = runnable_kernels();
  return copies;
}

// Where a node runs: its phase (a barrier between phases), partition
// (thread), tile and level; one struct, as the pass that computes them reads
// a dependency's four together.
struct NodeSchedule {
  std::uint32_t phase = 0, part = 0, tile = 0, level = 0;
};

// The nodes sorted by (phase, partition, tile, level, ring size, rank of the
// vertex): the rank is unique, so the order is total. The key packs into 64
// bits for any mesh the runtime takes (1.25M vertices: 50 bits), and sorting
// packed keys is ~5× faster than comparing tuples gathered per comparison
// (1.25M: 0.13–0.19 s against 0.7). A wider key (a hierarchy ~2^20 levels
// deep) falls back to the tuples.
std::vector<NodeId> traversal_order(const Hierarchy& h, const std::vector<NodeSchedule>& at, const std::vector<Index>& rank,
                                    const std::vector<Index>& curve, const std::vector<NodeId>& node_of) {
  const std::size_t n_nodes = h.node_count();
  std::vector<NodeId> sorted(n_nodes);
  NodeSchedule most;
  for (const NodeSchedule& s : at)
    most = {std::max(most.phase, s.phase), std::max(most.part, s.part), std::max(most.tile, s.tile), std::max(most.level, s.level)};
  const int rank_bits = std::bit_width(h.vertex_count()), ring_bits = std::bit_width(kMaxRingSize);
  const int phase_bits = std::bit_width(most.phase), part_bits = std::bit_width(most.part), tile_bits = std::bit_width(most.tile),
            level_bits = std::bit_width(most.level);
  if (phase_bits + part_bits + tile_bits + level_bits + ring_bits + rank_bits > 64) {
    for (std::size_t k = 0; k < n_nodes; ++k) sorted[k] = static_cast<NodeId>(k);
    auto key = [&](NodeId k) { return std::tuple(at[k].phase, at[k].part, at[k].tile, at[k].level, h.ring_size(k), rank[h.node_vertex[k]]); };
    std::sort(sorted.begin(), sorted.end(), [&](NodeId a, NodeId b) { return key(a) < key(b); });
    return sorted;
  }
  std::vector<std::uint64_t> keys(n_nodes);
  for (std::size_t k = 0; k < n_nodes; ++k) {
    std::uint64_t key = at[k].phase;
    key = (key << part_bits) | at[k].part;
    key = (key << tile_bits) | at[k].tile;
    key = (key << level_bits) | at[k].level;
    key = (key << ring_bits) | h.ring_size(static_cast<NodeId>(k));
    keys[k] = (key << rank_bits) | rank[h.node_vertex[k]];
  }
  std::sort(keys.begin(), keys.end());
  const std::uint64_t rank_mask = (std::uint64_t{1} << rank_bits) - 1;
  for (std::size_t i = 0; i < n_nodes; ++i) sorted[i] = node_of[curve[keys[i] & rank_mask]];
  return sorted;
}

}  // namespace

std::vector<std::string_view> DirectRecovery::kernels() {
  std::vector<std::string_view> names;
  for (const KernelCopy& k : kernel_copies()) names.push_back(k.name);
  return names;
}

std::string_view DirectRecovery::kernel() const { return kernel_copies()[kernel_].name; }

DirectRecovery::DirectRecovery(const Hierarchy& h, std::size_t partitions, std::string_view kernel)
    : base_count_(h.base_vertices.size()), node_count_(h.node_count()), base_vertices_(h.base_vertices) {
  const std::vector<KernelCopy>& copies = kernel_copies();
  kernel_ = copies.size() - 1;
  if (!kernel.empty()) {
    const auto named = std::find_if(copies.begin(), copies.end(), [&](const KernelCopy& k) { return k.name == kernel; });
    if (named == copies.end()) throw std::invalid_argument("no recovery kernel '" + std::string(kernel) + "' runs on this processor");
    kernel_ = static_cast<std::size_t>(named - copies.begin());
  }
  const std::size_t n_nodes = h.node_count();
  // Node k reads the positions of its ring vertices: it depends on the nodes
  // that removed them (those not in the base), which have larger ids. (The
  // cut's parents, NodeGraph, give the same levels and phases below: each is
  // a longest path, and every such dependency is a chain of parents.)
  const std::vector<NodeId> node_of = vertex_nodes(h);

  // Tiles: runs of kTileVertices consecutive vertices along a Morton curve
  // (for the service's sessions, whose vertex order is that curve, runs of
  // ids). A tile's nodes run together, so their ring reads and output writes
  // stay within a cache-sized window instead of every level sweeping the
  // whole mesh. Partitions (for threads) are contiguous runs of the curve.
  const std::vector<Index> curve = locality_order(h.rest_positions);
  std::vector<Index> rank(h.vertex_count());
  for (Index i = 0; i < curve.size(); ++i) rank[curve[i]] = i;
  partitions_ = partitions ? partitions
                           : std::clamp<std::size_t>(n_nodes / kNodesPerThread, 1,
                                                     std::min<std::size_t>(kMaxPartitions, std::max(1u, std::thread::hardware_concurrency())));
  // Level = 1 + the deepest dependency's level. A node runs in its own
  // partition, in the first phase after every dependency of another
  // partition (phases are separated by a barrier); within a partition and
  // phase, by (tile, level), its tile raised to its dependencies' there so
  // that the order stays valid. One descending pass sees every dependency
  // first.
  std::vector<NodeSchedule> at(n_nodes);
  std::array<NodeId, kMaxRingSize> deps;
  for (std::size_t k = n_nodes; k-- > 0;) {
    if (h.ring_size(static_cast<NodeId>(k)) > deps.size()) throw std::invalid_argument("hierarchy has a ring larger than any it can store");
    std::size_t n_deps = 0;
    for_each_ring_dependency(h, node_of, static_cast<NodeId>(k), [&](NodeId p) { deps[n_deps++] = p; });
    const Index r = rank[h.node_vertex[k]];
    std::uint32_t lv = 0, ph = 0, tl = static_cast<std::uint32_t>(r / kTileVertices);
    // Partitions split the curve evenly, not by whole tiles: a mesh of a
    // tile or two still uses every thread.
    const auto pt = static_cast<std::uint32_t>(std::uint64_t{r} * partitions_ / h.vertex_count());
    for (std::size_t i = 0; i < n_deps; ++i) {
      const NodeSchedule& p = at[deps[i]];
      lv = std::max(lv, p.level + 1);
      ph = std::max(ph, p.phase + (p.part != pt ? 1u : 0u));
    }
    for (std::size_t i = 0; i < n_deps; ++i)
      if (const NodeSchedule& p = at[deps[i]]; p.part == pt && p.phase == ph) tl = std::max(tl, p.tile);
    at[k] = {ph, pt, tl, lv};
  }
  std::uint32_t last_phase = 0;
  for (const NodeSchedule& s : at) last_phase = std::max(last_phase, s.phase);
  const std::size_t phases = last_phase + 1;
  // Within a tile and level, by ring size: a block is padded to its largest
  // ring, so like rings together pad less (1.25M vertices: 124 bytes a
  // frame per vertex instead of 129).
  const std::vector<NodeId> sorted = traversal_order(h, at, rank, curve, node_of);

  // Blocks of W nodes of one (phase, partition, tile, level): never dependent
  // on each other. Segment phase·partitions + partition is a run of blocks.
  std::vector<NodeId> order;  // nodes in traversal order, kNone for padding lanes
  order.reserve(n_nodes + n_nodes / 4);
  segment_blocks_.clear();
  auto segment_of = [&](NodeId k) { return at[k].phase * partitions_ + at[k].part; };
  for (std::size_t i = 0; i < n_nodes; ++i) {
    const NodeId k = sorted[i];
    // A segment's first node marks where it starts, and where the empty
    // segments before it start and end. (Marking where each segment ended
    // instead gave an empty segment the blocks of the one after it: a node
    // then ran in the phase before its parent's, on another thread.)
    while (segment_blocks_.size() <= segment_of(k)) segment_blocks_.push_back(static_cast<std::uint32_t>(order.size() / W));
    order.push_back(k);
    const bool last = i + 1 == n_nodes;
    const NodeId next = last ? k : sorted[i + 1];
    if (last || segment_of(next) != segment_of(k) || at[next].tile != at[k].tile || at[next].level != at[k].level)
      while (order.size() % W) order.push_back(kNone);
  }
  while (segment_blocks_.size() < phases * partitions_ + 1) segment_blocks_.push_back(static_cast<std::uint32_t>(order.size() / W));
  phases_ = phases;

  if (base_count_ + order.size() >= (std::size_t{1} << 30))
    throw std::invalid_argument("hierarchy too large for the runtime's 32-bit ring indices (" + std::to_string(h.vertex_count()) + " vertices)");
  slot_of_vertex_.assign(h.vertex_count(), 0);
  for (Index i = 0; i < base_count_; ++i) slot_of_vertex_[h.base_vertices[i]] = i;
  vertex_of_slot_.assign(order.size(), kNone);
  for (std::size_t i = 0; i < order.size(); ++i) {
    if (order[i] == kNone) continue;
    vertex_of_slot_[i] = h.node_vertex[order[i]];
    slot_of_vertex_[h.node_vertex[order[i]]] = static_cast<Index>(base_count_ + i);
  }

  // Each block padded to its largest ring: sized first, so that the arrays
  // are allocated once, then filled on a thread per partition (blocks are
  // independent; the fill is mostly cache misses into the hierarchy, in
  // traversal order rather than node order).
  const std::size_t blocks = order.size() / W;
  block_ring_.assign(blocks + 1, 0);
  for (std::size_t blk = 0; blk < blocks; ++blk) {
    std::size_t ring = 1;
    for (std::size_t l = 0; l < W; ++l)
      if (const NodeId k = order[blk * W + l]; k != kNone) ring = std::max(ring, h.ring_size(k));
    if (ring > kMaxRing)
      throw std::invalid_argument("hierarchy has a ring of " + std::to_string(ring) + " vertices; the runtime supports at most " +
                                  std::to_string(kMaxRing));
    block_ring_[blk + 1] = static_cast<std::uint32_t>(block_ring_[blk] + ring);
  }
  offset_.resize(3 * W * blocks);
  lane_ring_.resize(W * blocks);
  ring_slot_.resize(std::size_t{block_ring_.back()} * W);
  ring_weight_.resize(std::size_t{block_ring_.back()} * W);
  const auto fill = [&](std::size_t first_block, std::size_t end_block) {
    for (std::size_t blk = first_block; blk < end_block; ++blk) {
      const std::size_t first = std::size_t{block_ring_[blk]} * W, ring = block_ring_[blk + 1] - block_ring_[blk];
      for (std::size_t l = 0; l < W; ++l) {
        const NodeId k = order[blk * W + l];
        if (k == kNone) {
          // Padding lanes read slot 0 with weight 1: a finite result nobody reads.
          for (std::size_t i = 0; i < ring; ++i) ring_slot_[first + i * W + l] = 0, ring_weight_[first + i * W + l] = i == 0 ? 1.0f : 0.0f;
          for (int c = 0; c < 3; ++c) offset_[(3 * blk + c) * W + l] = 0.0f;
          lane_ring_[blk * W + l] = 1;
          continue;
        }
        const auto r = h.ring(k);
        const auto w = h.weights(k);
        double sum = 0.0;  // the stored weights are relative (Hierarchy::ring_weights)
        for (std::uint16_t wi : w) sum += wi;
        for (std::size_t i = 0; i < ring; ++i) {
          const bool real = i < r.size();
          ring_slot_[first + i * W + l] = 4 * slot_of_vertex_[r[real ? i : 0]];  // the float index: no shift per load
          ring_weight_[first + i * W + l] = real ? static_cast<float>(w[i] / sum) : 0.0f;
        }
        for (int c = 0; c < 3; ++c) offset_[(3 * blk + c) * W + l] = static_cast<float>(h.node_offset[k][c]);
        lane_ring_[blk * W + l] = static_cast<std::uint8_t>(r.size() | (h.node_closed[k] ? 0 : kOpenRing));
      }
    }
  };
  parallel_ranges(blocks, partitions_, fill);

  check_schedule();

  std::vector<Vec3> base_rest(base_count_);
  Vec3 centroid = Vec3::Zero();
  for (std::size_t i = 0; i < base_count_; ++i) centroid += base_rest[i] = h.rest_positions[h.base_vertices[i]];
  if (base_count_ > 0) centroid /= static_cast<double>(base_count_);
  rest_origin_ = {centroid.x(), centroid.y(), centroid.z()};
  origin_step_ = std::max(bounding_box_diagonal(h.rest_positions), 1e-300);
  // The float error of the rest pose, kept per node (see the header).
  rest_error_.assign(offset_.size(), 0.0f);
  RecoveryWorkspace ws;
  std::vector<Vec3> recovered(h.vertex_count());
  recover(base_rest, ws, recovered, static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  for (std::size_t i = 0; i < order.size(); ++i) {
    if (order[i] == kNone) continue;
    const std::size_t blk = i / W, l = i % W;
    const Index v = h.node_vertex[order[i]];
    for (int c = 0; c < 3; ++c) rest_error_[(3 * blk + c) * W + l] = static_cast<float>(h.rest_positions[v][c] - recovered[v][c]);
  }
}

std::array<double, 3> DirectRecovery::origin_for(std::span<const Vec3> base) const {
  // The rest base centroid, unless the pose's centroid is a mesh size or more
  // away: then moved by whole steps, so that small motions keep exactly the
  // rest's floats where the pose does not move.
  Vec3 centroid = Vec3::Zero();
  for (const Vec3& q : base) centroid += q;
  if (!base.empty()) centroid /= static_cast<double>(base.size());
  std::array<double, 3> origin = rest_origin_;
  for (int c = 0; c < 3; ++c) origin[c] += origin_step_ * std::round((centroid[c] - rest_origin_[c]) / origin_step_);
  return origin;
}

void DirectRecovery::recover(std::span<const Vec3> base, RecoveryWorkspace& ws, std::span<Vec3> out, int threads) const {
  if (base.size() != base_count_)
    throw std::invalid_argument("direct recovery needs " + std::to_string(base_count_) + " base positions, got " +
                                std::to_string(base.size()));
  if (out.size() != slot_of_vertex_.size())
    throw std::invalid_argument("output has room for " + std::to_string(out.size()) + " vertices, the mesh has " +
                                std::to_string(slot_of_vertex_.size()));
  ws.xyzw.resize(scratch_floats());
  float* p = ws.xyzw.data();
  ws.origin = origin_for(base);
  for (std::size_t i = 0; i < base_count_; ++i) {
    out[base_vertices_[i]] = base[i];
    for (int c = 0; c < 3; ++c) p[4 * i + c] = static_cast<float>(base[i][c] - ws.origin[c]);
  }

  const Layout layout{block_ring_.data(), ring_slot_.data(),  ring_weight_.data(),    offset_.data(),
                      lane_ring_.data(),  rest_error_.data(), vertex_of_slot_.data(), base_count_};
  const Output o{out.data()->data(), ws.origin[0], ws.origin[1], ws.origin[2]};
  const std::size_t t = std::min<std::size_t>(std::max(threads, 1), partitions_);
  const BlocksFn run = kernel_copies()[kernel_].run;
  if (t == 1) {
    run(layout, 0, segment_blocks_.back(), p, o);
    return;
  }
  // Helpers kept by the process rather than a thread started per frame;
  // with fewer idle than asked, fewer threads take the partitions.
  HelperTeam::Crew crew = HelperTeam::shared().reserve(t - 1);
  const std::size_t n = crew.threads();
  // Thread `id` runs its partitions of every phase; a barrier between phases.
  SpinBarrier sync(static_cast<std::uint32_t>(n));
  crew.run([&](std::size_t id) {
    const std::size_t first = partitions_ * id / n, last = partitions_ * (id + 1) / n;
    for (std::size_t ph = 0; ph < phases_; ++ph) {
      run(layout, segment_blocks_[ph * partitions_ + first], segment_blocks_[ph * partitions_ + last], p, o);
      if (n > 1) sync.arrive_and_wait();
    }
  });
}

void DirectRecovery::check_schedule() const {
  std::vector<std::uint32_t> segment(blocks());
  for (std::size_t s = 0; s + 1 < segment_blocks_.size(); ++s)
    std::fill(segment.begin() + segment_blocks_[s], segment.begin() + segment_blocks_[s + 1], static_cast<std::uint32_t>(s));
  for (std::size_t b = 0; b < segment.size(); ++b) {
    for (std::size_t r = std::size_t{block_ring_[b]} * W; r < std::size_t{block_ring_[b + 1]} * W; ++r) {
      const std::size_t slot = ring_slot_[r] / 4;
      if (slot < base_count_) continue;
      const std::size_t writer = (slot - base_count_) / W;
      const bool earlier_phase = segment[writer] / partitions_ < segment[b] / partitions_;
      if (!earlier_phase && !(segment[writer] == segment[b] && writer < b))
        throw std::logic_error("direct recovery layout: block " + std::to_string(b) + " (phase " +
                               std::to_string(segment[b] / partitions_) + ", partition " + std::to_string(segment[b] % partitions_) +
                               ") reads a position block " + std::to_string(writer) + " (phase " +
                               std::to_string(segment[writer] / partitions_) + ", partition " +
                               std::to_string(segment[writer] % partitions_) + ") has not written yet");
    }
  }
}

std::size_t DirectRecovery::critical_blocks() const {
  std::size_t blocks = 0;
  for (std::size_t ph = 0; ph < phases_; ++ph) {
    std::size_t busiest = 0;
    for (std::size_t q = 0; q < partitions_; ++q)
      busiest = std::max<std::size_t>(busiest, segment_blocks_[ph * partitions_ + q + 1] - segment_blocks_[ph * partitions_ + q]);
    blocks += busiest;
  }
  return blocks;
}

std::size_t DirectRecovery::bytes_per_frame() const {
  const std::size_t slots = base_count_ + vertex_of_slot_.size();
  return ring_slot_.size() * sizeof(std::uint32_t) + ring_weight_.size() * sizeof(float) + offset_.size() * sizeof(float) +
         rest_error_.size() * sizeof(float) + vertex_of_slot_.size() * sizeof(Index) + lane_ring_.size() +
         block_ring_.size() * sizeof(std::uint32_t)  // the layout, read once
         + slots * 4 * sizeof(float)                 // every slot written once
         + slot_of_vertex_.size() * sizeof(Vec3);    // every result written once
}

std::size_t DirectRecovery::memory_bytes() const {
  return base_vertices_.capacity() * sizeof(Index) + slot_of_vertex_.capacity() * sizeof(Index) +
         vertex_of_slot_.capacity() * sizeof(Index) +
         segment_blocks_.capacity() * 4 + block_ring_.capacity() * 4 + ring_slot_.capacity() * 4 + ring_weight_.capacity() * 4 +
         offset_.capacity() * 4 + lane_ring_.capacity() + rest_error_.capacity() * 4;
}

}  // namespace filigree
