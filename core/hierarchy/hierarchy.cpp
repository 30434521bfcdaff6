#include "hierarchy/hierarchy.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <optional>
#include <sstream>
#include <thread>
#include <type_traits>

namespace filigree {
namespace {

[[noreturn]] void fail(const std::string& what) { throw HierarchyError("invalid hierarchy: " + what); }

template <class T>
std::string str(const T& v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

template <class V>
bool finite(const V& v) {
  return std::isfinite(v.x()) && std::isfinite(v.y()) && std::isfinite(v.z());
}

// One bit per vertex or face: the validation's "seen" sets, small enough to
// stay in cache where a NodeId per face (26 MB at 1.25M vertices) did not.
class Bits {
 public:
  explicit Bits(std::size_t n) : words_((n + 63) / 64, 0) {}
  bool test(std::size_t i) const { return (words_[i / 64] >> (i % 64)) & 1u; }
  // Any i: out of range is clamped (a prefetch of unchecked data). Always
  // inlined: GCC's IPA deems a function that only prefetches pure and
  // deletes the calls.
  [[gnu::always_inline]] void prefetch(std::size_t i) const {
    if (!words_.empty()) __builtin_prefetch(&words_[std::min(i / 64, words_.size() - 1)], 1);
  }
  // Sets bit i; returns whether it was set before.
  bool test_and_set(std::size_t i) {
    const std::uint64_t mask = std::uint64_t{1} << (i % 64);
    const bool was = words_[i / 64] & mask;
    words_[i / 64] |= mask;
    return was;
  }
  // Calls fn(i) for every clear bit i < n, ascending, a word at a time (a
  // loaded hierarchy has almost every bit set).
  template <class Fn>
  void for_each_clear(std::size_t n, Fn&& fn) const {
    for (std::size_t w = 0; w < words_.size(); ++w) {
      for (std::uint64_t clear = ~words_[w]; clear != 0; clear &= clear - 1) {
        const std::size_t i = 64 * w + static_cast<std::size_t>(std::countr_zero(clear));
        if (i < n) fn(i);
      }
    }
  }

 private:
  std::vector<std::uint64_t> words_;
};

void check_offsets(std::span<const Index> offsets, std::size_t nodes, std::size_t data, const char* name) {
  if (offsets.size() != nodes + 1) fail(std::string(name) + " offsets: " + str(offsets.size()) + " entries for " + str(nodes) + " nodes");
  if (offsets.front() != 0 || offsets.back() != data) fail(std::string(name) + " offsets do not span their data");
  for (std::size_t k = 0; k < nodes; ++k)
    if (offsets[k] > offsets[k + 1]) fail(std::string(name) + " offsets decrease at node " + str(k));
}

// Valid offsets assumed: a hole needs 3 corners, and RingCorners address 255.
void check_ring_sizes(std::span<const Index> ring_offsets) {
  for (std::size_t k = 0; k + 1 < ring_offsets.size(); ++k) {
    const std::size_t size = ring_offsets[k + 1] - ring_offsets[k];
    if (size < 3 || size > kMaxRingSize) fail("node " + str(k) + " has a ring of " + str(size) + " vertices");
  }
}

// Whether `tris` (corners < r, each triangle's distinct) triangulate the
// ring's polygon consistently with its fan: every ring edge i → i+1 (the
// closing one r−1 → 0 too) once, every other edge once each way. Then the
// hole closes into a manifold disc with every ring vertex on it. O(r) for
// the rings the simplifier makes (diagonals paired by a scan).
bool is_ring_triangulation(std::span<const RingCorners> tris, std::size_t r) {
  std::array<std::uint64_t, 4> ring_edge{};  // r ≤ kMaxRingSize < 256
  std::array<std::array<std::uint8_t, 2>, 3 * kMaxRingSize> diagonal;
  std::size_t diagonals = 0, ring_edges = 0;
  for (const RingCorners& t : tris) {
    for (int c = 0; c < 3; ++c) {
      const std::size_t a = t[c], b = t[(c + 1) % 3];
      if (b == (a + 1 == r ? 0 : a + 1)) {
        const std::uint64_t bit = std::uint64_t{1} << (a % 64);
        if (ring_edge[a / 64] & bit) return false;
        ring_edge[a / 64] |= bit;
        ++ring_edges;
      } else {
        diagonal[diagonals++] = {t[c], t[(c + 1) % 3]};
      }
    }
  }
  if (ring_edges != r) return false;
  for (std::size_t i = 0; i < diagonals; ++i) {
    std::size_t same = 0, reverse = 0;
    for (std::size_t j = 0; j < diagonals; ++j) {
      same += diagonal[j] == diagonal[i];
      reverse += diagonal[j][0] == diagonal[i][1] && diagonal[j][1] == diagonal[i][0];
    }
    if (same != 1 || reverse != 1) return false;
  }
  return true;
}

// Index of node k's first face among the created ones (valid ring offsets
// assumed; Hierarchy::first_created_face adds the original faces).
std::size_t first_created(std::span<const Index> ring_offsets, std::size_t k) { return ring_offsets[k] - 2 * k; }

// What the checks of a stored hierarchy leave behind for hierarchy_from().
struct Checked {
  Bits removed_vertices{0};      // per vertex: removed by some node
  std::vector<FaceId> base_faces;  // the faces alive at the end, ascending
};

// Index of the first element of `a` for which bad(x) holds, or a.size(): one
// tight pass without early exits while nothing is wrong, a second one only to
// name the culprit.
template <class T, class Bad>
std::size_t first_bad(std::span<const T> a, Bad bad) {
  bool any = false;
  for (const T& x : a) any |= bad(x);
  if (!any) return a.size();
  std::size_t i = 0;
  while (!bad(a[i])) ++i;
  return i;
}

// x − x is 0 for every finite x, NaN for ±inf and NaN.
template <class F>
bool not_finite(F x) {
  return x - x != F(0);
}

// The coordinates of an array of 3-vectors, as one flat array.
template <class V>
std::span<const typename V::Scalar> coordinates(std::span<const V> a) {
  static_assert(sizeof(V) == 3 * sizeof(typename V::Scalar));
  return {a.empty() ? nullptr : a.data()->data(), 3 * a.size()};
}

// A removed vertex's ring is open exactly when the vertex is on the original
// mesh's boundary (simplification keeps every vertex's boundary status): the
// first node whose closed flag says otherwise, as a message. A vertex is
// inside when its faces' next corners are their previous corners over again
// (a closed fan): compared as sums of a 64-bit mix of the ids, one pass over
// the faces, no edge table. Safe on any input: with a face corner or a
// node's vertex out of range it says nothing (check() reports those).
std::optional<std::string> boundary_mismatch(const StoredHierarchy& s) {
  const std::size_t n = s.rest_positions.size(), nodes = s.node_vertex.size();
  if (s.node_closed.size() != nodes) return std::nullopt;
  std::vector<std::uint64_t> balance(n, 0);  // Σ mix(next corner) − Σ mix(previous corner)
  const auto mix = [](Index v) {
    std::uint64_t x = (static_cast<std::uint64_t>(v) + 1) * 0x9E3779B97F4A7C15ull;
    x ^= x >> 31;
    return x * 0xBF58476D1CE4E5B9ull;
  };
  for (const Triangle& t : s.original_faces) {
    if (t[0] >= n || t[1] >= n || t[2] >= n) return std::nullopt;
    for (int i = 0; i < 3; ++i) balance[t[i]] += mix(t[(i + 1) % 3]) - mix(t[(i + 2) % 3]);
  }
  for (std::size_t k = 0; k < nodes; ++k) {
    if (s.node_vertex[k] >= n) return std::nullopt;
    if ((balance[s.node_vertex[k]] == 0) != (s.node_closed[k] != 0))
      return "node " + str(k) + " says its ring is " + (s.node_closed[k] ? "closed" : "open") + ", but its vertex is " +
             (s.node_closed[k] ? "on" : "not on") + " the mesh's boundary";
  }
  return std::nullopt;
}

// Whether check() runs boundary_mismatch() itself, or leaves it to its
// caller (who runs it on another thread).
enum class Boundaries { kCheck, kLeftToCaller };

Checked check(const StoredHierarchy& s, Boundaries boundaries = Boundaries::kCheck) {
  const std::size_t n = s.rest_positions.size();
  const std::size_t nodes = s.node_vertex.size();
  const std::size_t slots = s.ring_vertices.size();
  const std::size_t original = s.original_faces.size();
  if (n == 0) fail("no vertices");
  if (n >= kNone || nodes >= kNone || slots >= kNone) fail("more elements than 32-bit indices address");
  if (const std::size_t i = first_bad(coordinates(s.rest_positions), not_finite<double>); i < 3 * n)
    fail("vertex " + str(i / 3) + " has a non-finite coordinate");
  if (original == 0) fail("original face count 0 out of range");
  const std::span<const Index> corners{s.original_faces.data()->data(), 3 * original};
  if (const std::size_t i = first_bad(corners, [n](Index v) { return v >= n; }); i < corners.size())
    fail("face " + str(i / 3) + " has vertex " + str(corners[i]) + " >= " + str(n));

  if (s.node_closed.size() != nodes || s.node_offset.size() != nodes) fail("per-node arrays differ in length");
  check_offsets(s.ring_offsets, nodes, slots, "ring");
  check_ring_sizes(s.ring_offsets);
  if (s.ring_weights.size() != slots) fail("ring weights and ring vertices differ in length");
  // Every ring has ≥ 3 slots, so slots ≥ 3·nodes and this does not wrap.
  if (s.created_corners.size() != slots - 2 * nodes) fail("created faces: " + str(s.created_corners.size()) + ", the rings make " + str(slots - 2 * nodes));
  const std::size_t faces = original + s.created_corners.size();
  if (faces >= kNone) fail("more faces than 32-bit indices address");
  if (s.maps_face.size() != n || s.maps_bary.size() != n) fail("per-vertex arrays do not have one entry per vertex");

  // Per-element checks that need no node context, in flat passes.
  const auto node_of_slot = [&](std::size_t j) {
    return static_cast<std::size_t>(std::upper_bound(s.ring_offsets.begin(), s.ring_offsets.end(), j) - s.ring_offsets.begin() - 1);
  };
  if (const std::size_t j = first_bad(s.ring_vertices, [n](Index v) { return v >= n; }); j < slots)
    fail("node " + str(node_of_slot(j)) + " has an invalid ring vertex");
  if (const std::size_t j = first_bad(s.ring_weights, [](std::uint16_t w) { return w == 0; }); j < slots)
    fail("node " + str(node_of_slot(j)) + " has a zero ring weight");
  if (const std::size_t i = first_bad(coordinates(s.node_offset), not_finite<float>); i < 3 * nodes)
    fail("node " + str(i / 3) + " has a non-finite offset");
  if (const std::size_t k = first_bad(s.node_closed, [](std::uint8_t b) { return b > 1; }); k < nodes)
    fail("node " + str(k) + " has an invalid closed flag");
  if (const std::size_t k = first_bad(s.node_vertex, [n](Index v) { return v >= n; }); k < nodes)
    fail("node " + str(k) + " and its vertex disagree");

  Checked c{Bits(n), {}};
  for (std::size_t k = 0; k < nodes; ++k)
    if (c.removed_vertices.test_and_set(s.node_vertex[k])) fail("node " + str(k) + " removes vertex " + str(s.node_vertex[k]) + ", removed before");

  if (boundaries == Boundaries::kCheck)
    if (const std::optional<std::string> why = boundary_mismatch(s)) fail(*why);

  // Rings, last node first: a ring vertex is a base vertex or one removed
  // later (so direct recovery, in descending node order, has placed it).
  // Created faces: a triangulation of the ring's polygon.
  Bits later(n);
  std::size_t fans = 0;
  for (std::size_t k = nodes; k-- > 0;) {
    const Index v = s.node_vertex[k];
    const std::size_t first = s.ring_offsets[k], size = s.ring_offsets[k + 1] - first;
    bool bad = false;
    for (std::size_t j = first; j < first + size; ++j) {
      const Index u = s.ring_vertices[j];
      bad |= u == v || (c.removed_vertices.test(u) && !later.test(u));
    }
    if (bad) {
      for (std::size_t j = first; j < first + size; ++j)
        if (const Index u = s.ring_vertices[j]; u == v || (c.removed_vertices.test(u) && !later.test(u)))
          fail("node " + str(k) + " has ring vertex " + str(u) + (u == v ? ", its own vertex" : ", removed before it"));
    }
    later.test_and_set(v);
    fans += size - (s.node_closed[k] ? 0 : 1);

    const std::span<const RingCorners> made = s.created_corners.subspan(first_created(s.ring_offsets, k), size - 2);
    bool outside = false;
    for (const RingCorners& t : made)
      outside |= t[0] >= size || t[1] >= size || t[2] >= size || t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
    if (outside) fail("node " + str(k) + " creates a face with corners outside its ring");
    if (!is_ring_triangulation(made, size)) fail("node " + str(k) + "'s created faces do not triangulate its ring");
  }

  // The faces alive at the end are those with only base vertices (a face
  // dies with the first of its vertices removed), and as many as the
  // removals leave: every face, less one per fan slot.
  const auto base = [&](Index v) { return !c.removed_vertices.test(v); };
  if (fans <= faces) c.base_faces.reserve(faces - fans);
  for (std::size_t f = 0; f < original; ++f) {
    const Triangle& t = s.original_faces[f];
    if (base(t[0]) && base(t[1]) && base(t[2])) c.base_faces.push_back(static_cast<FaceId>(f));
  }
  for (std::size_t k = 0; k < nodes; ++k) {
    const Index* r = s.ring_vertices.data() + s.ring_offsets[k];
    const std::size_t created = first_created(s.ring_offsets, k), size = s.ring_offsets[k + 1] - s.ring_offsets[k];
    for (std::size_t j = created; j < created + size - 2; ++j) {
      const RingCorners& t = s.created_corners[j];
      if (base(r[t[0]]) && base(r[t[1]]) && base(r[t[2]])) c.base_faces.push_back(static_cast<FaceId>(original + j));
    }
  }
  if (fans > faces || c.base_faces.size() != faces - fans)
    fail("the removals delete " + str(fans) + " of " + str(faces) + " faces, but " + str(c.base_faces.size()) + " have only base vertices");

  const std::size_t base_faces = c.base_faces.size();
  if (const std::size_t v = first_bad(s.maps_face, [base_faces](Index f) { return f >= base_faces; }); v < n)
    fail("vertex " + str(v) + " is parameterised in a face outside the base mesh");
  if (const std::size_t v = first_bad(s.maps_bary, [](const Barycentric16& b) { return b[0] + b[1] > 65535; }); v < n)
    fail("vertex " + str(v) + " has invalid barycentric coordinates");
  return c;
}
// out = in: a view of it kept alive by `storage`, or (no storage) a copy,
// allocated exactly (a loaded hierarchy holds no slack) and not zero-filled
// first. (Advising copies onto transparent huge pages took the load from
// ~400 to ~250 ms where huge pages are cheap, but to 0.8–1.1 s one time in
// three on a VM that reports free 8 MB blocks to its host, so it is not
// done.)
template <class T>
void take(MappedArray<T>& out, std::span<const T> in, const std::shared_ptr<const void>& storage) {
  if (storage) {
    out = MappedArray<T>::view(in, storage);
    return;
  }
  std::vector<T> copy;
  copy.reserve(in.size());
  if constexpr (std::is_trivially_copyable_v<T>) {
    copy.assign(in.begin(), in.end());
  } else {
    // Eigen vectors: plain floats, but not trivially copyable by type; their
    // default constructor leaves them uninitialised, so resize costs nothing.
    copy.resize(in.size());
    if (!in.empty()) std::memcpy(static_cast<void*>(copy.data()), in.data(), in.size() * sizeof(T));
  }
  out = std::move(copy);
}

template <class T>
std::size_t bytes_of(const std::vector<T>& v) {
  return v.capacity() * sizeof(T);
}

}  // namespace

NodeId Hierarchy::creator(FaceId f) const {
  if (f < original_faces.size()) return kNone;
  if (f >= face_count()) throw std::out_of_range("face " + str(f) + " out of range");
  // The last node whose first created face is ≤ f (first_created_face ascends).
  std::size_t lo = 0, hi = node_count();
  while (hi - lo > 1) {
    const std::size_t mid = (lo + hi) / 2;
    (first_created_face(static_cast<NodeId>(mid)) <= f ? lo : hi) = mid;
  }
  return static_cast<NodeId>(lo);
}

Triangle Hierarchy::face(FaceId f) const {
  if (f < original_faces.size()) return original_faces[f];
  const NodeId k = creator(f);
  return created_face(k, f - first_created_face(k));
}

TriMesh Hierarchy::original_mesh() const {
  TriMesh m;
  m.positions = rest_positions.to_vector();
  m.faces = original_faces.to_vector();
  return m;
}

TriMesh Hierarchy::base_mesh() const {
  std::vector<Index> local(rest_positions.size(), kNone);
  TriMesh m;
  for (Index i = 0; i < base_vertices.size(); ++i) {
    local[base_vertices[i]] = i;
    m.positions.push_back(rest_positions[base_vertices[i]]);
  }
  m.faces.reserve(base_faces.size());
  for (FaceId f : base_faces) {
    const Triangle t = face(f);
    m.faces.push_back({local[t[0]], local[t[1]], local[t[2]]});
  }
  return m;
}

Vec3 Hierarchy::maps_barycentric(Index i) const {
  const double b0 = maps_bary[i][0] / kFixedPointOne, b1 = maps_bary[i][1] / kFixedPointOne;
  return {b0, b1, std::max(0.0, 1.0 - b0 - b1)};
}

Vec3 Hierarchy::maps_position(Index i, std::span<const Vec3> positions) const {
  const Triangle t = face(base_faces[maps_face[i]]);
  const Vec3 b = maps_barycentric(i);
  return b[0] * positions[t[0]] + b[1] * positions[t[1]] + b[2] * positions[t[2]];
}

std::size_t Hierarchy::depth() const {
  // The nodes a node depends on have larger ids: in descending order their
  // chains are final when it is reached.
  const std::vector<NodeId> node_of = vertex_nodes(*this);
  std::vector<std::uint32_t> d(node_count(), 1);
  std::size_t deepest = 0;
  for (std::size_t k = node_count(); k-- > 0;) {
    for_each_ring_dependency(*this, node_of, static_cast<NodeId>(k), [&](NodeId p) { d[k] = std::max(d[k], d[p] + 1); });
    deepest = std::max<std::size_t>(deepest, d[k]);
  }
  return deepest;
}

std::vector<NodeId> vertex_nodes(const Hierarchy& h) {
  std::vector<NodeId> node_of(h.vertex_count(), kNone);
  for (std::size_t k = 0; k < h.node_count(); ++k) node_of[h.node_vertex[k]] = static_cast<NodeId>(k);
  return node_of;
}

std::uint16_t quantize_ring_weight(double w) {
  return static_cast<std::uint16_t>(std::clamp(std::lround(w * kFixedPointOne), 1L, 65535L));
}

std::vector<std::uint16_t> quantize_ring_weights(std::span<const double> weights) {
  std::vector<std::uint16_t> q(weights.size());
  for (std::size_t i = 0; i < weights.size(); ++i) q[i] = quantize_ring_weight(weights[i]);
  return q;
}

Barycentric16 quantize_barycentric(const Vec3& b) {
  const long b0 = std::clamp(std::lround(b[0] * kFixedPointOne), 0L, 65535L);
  const long b1 = std::clamp(std::lround(b[1] * kFixedPointOne), 0L, 65535L - b0);
  return {static_cast<std::uint16_t>(b0), static_cast<std::uint16_t>(b1)};
}

std::size_t Hierarchy::memory_bytes() const {
  return rest_positions.bytes() + original_faces.bytes() + created_corners.bytes() + node_vertex.bytes() + node_closed.bytes() +
         ring_offsets.bytes() + ring_vertices.bytes() + ring_weights.bytes() + node_offset.bytes() + bytes_of(base_vertices) +
         bytes_of(base_faces) + maps_face.bytes() + maps_bary.bytes();
}

void validate_hierarchy(const StoredHierarchy& s) { check(s); }

Hierarchy hierarchy_from(const StoredHierarchy& s, const std::shared_ptr<const void>& storage, const std::function<void()>& concurrently) {
  Hierarchy h;
  // In place: each array views `s`, kept alive by `storage`. Otherwise
  // copied as they are: the copies need no checks first (nothing indexes
  // with their values until the checks pass), and the checks and
  // derivations read only `s`. So a helper thread runs `concurrently` and
  // the boundary check (a third of the checks' time), then copies, while
  // this one runs the other checks and derives, then copies too: each array
  // goes to whichever thread is free first, largest first. (Copying is
  // mostly first touches of fresh memory, which cost ~2 ms a MB on a VM
  // whose host backs pages lazily: 1.25M vertices, four loads in one
  // process, 400–661 ms with the helper copying alone.)
  using Take = void (*)(Hierarchy&, const StoredHierarchy&, const std::shared_ptr<const void>&);
  static constexpr auto kTakes = std::to_array<Take>({
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.rest_positions, s.rest_positions, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.original_faces, s.original_faces, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.ring_vertices, s.ring_vertices, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.ring_weights, s.ring_weights, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.node_offset, s.node_offset, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.created_corners, s.created_corners, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.maps_face, s.maps_face, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.maps_bary, s.maps_bary, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.node_vertex, s.node_vertex, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.ring_offsets, s.ring_offsets, keep); },
      [](Hierarchy& h, const StoredHierarchy& s, const auto& keep) { take(h.node_closed, s.node_closed, keep); },
  });
  std::atomic<std::size_t> next_take{0};
  const auto take_left = [&] {
    for (std::size_t i; (i = next_take.fetch_add(1, std::memory_order_relaxed)) < kTakes.size();) kTakes[i](h, s, storage);
  };
  std::exception_ptr helper_error;
  std::optional<std::string> boundary_error;
  const auto helper_work = [&] {
    try {
      if (concurrently) concurrently();
      boundary_error = boundary_mismatch(s);
      take_left();
    } catch (...) {
      helper_error = std::current_exception();
    }
  };
  constexpr std::size_t kParallelVertices = 100000;  // below this a thread costs more than it saves
  const bool parallel = s.rest_positions.size() >= kParallelVertices && std::thread::hardware_concurrency() > 1;
  {
    std::jthread helper;  // joins when this scope ends, by return or by exception
    if (parallel) helper = std::jthread(helper_work);

    Checked c = check(s, Boundaries::kLeftToCaller);
    const std::size_t n = s.rest_positions.size(), nodes = s.node_vertex.size();
    h.base_vertices.reserve(n - nodes);
    c.removed_vertices.for_each_clear(n, [&](std::size_t v) { h.base_vertices.push_back(static_cast<Index>(v)); });
    h.base_faces = std::move(c.base_faces);  // reserved exactly by check()
    if (parallel) take_left();
  }
  if (!parallel) helper_work();
  if (helper_error) std::rethrow_exception(helper_error);
  if (boundary_error) fail(*boundary_error);
  return h;
}

StoredHierarchy stored_view(const Hierarchy& h) {
  check_offsets(h.ring_offsets, h.node_count(), h.ring_vertices.size(), "ring");
  return {h.rest_positions, h.original_faces, h.created_corners, h.node_vertex, h.node_closed, h.ring_offsets, h.ring_vertices,
          h.ring_weights, h.node_offset, h.maps_face, h.maps_bary};
}

void validate_hierarchy(const Hierarchy& h) {
  const Checked c = check(stored_view(h));
  const std::size_t n = h.vertex_count(), nodes = h.node_count();
  // Base mesh: exactly the never-removed vertices and faces, ascending.
  if (h.base_vertices.size() != n - nodes) fail("base vertex count does not match the removals");
  for (std::size_t i = 0; i < h.base_vertices.size(); ++i) {
    const Index v = h.base_vertices[i];
    if (v >= n || c.removed_vertices.test(v) || (i > 0 && h.base_vertices[i - 1] >= v)) fail("base vertex " + str(i) + " is invalid");
  }
  if (h.base_faces != c.base_faces) fail("base faces are not the faces the removals leave");
}

}  // namespace filigree
