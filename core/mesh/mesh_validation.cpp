// Mesh validation and repair. Everything is linear apart from small per-vertex
// sorts: edges and faces are bucketed by their lowest vertex (counting sort),
// so a multi-million-face mesh needs no map per edge.

#include "mesh/mesh_validation.h"

#include <algorithm>

#include <Eigen/Geometry>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <tuple>
#include <unordered_map>

namespace filigree {
namespace {

constexpr std::uint8_t kOutOfRange = 1;
constexpr std::uint8_t kDegenerate = 2;
constexpr std::uint8_t kDuplicate = 4;
constexpr Index kNone = std::numeric_limits<Index>::max();

bool has_repeated_index(const Triangle& f) { return f[0] == f[1] || f[1] == f[2] || f[0] == f[2]; }

// Union-find with path halving; the root of a set is its smallest member.
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t size) : parent_(size) { std::iota(parent_.begin(), parent_.end(), 0); }
  std::size_t find(std::size_t x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  void unite(std::size_t a, std::size_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<std::size_t> parent_;
};

// Bucket offsets for a counting sort: offsets[k]..offsets[k+1] is bucket k.
// `for_each_key(f)` must call f(key) once per item.
template <class ForEachKey>
std::vector<std::size_t> bucket_offsets(std::size_t key_count, ForEachKey for_each_key) {
  std::vector<std::size_t> offsets(key_count + 1, 0);
  for_each_key([&](std::size_t key) { ++offsets[key + 1]; });
  std::partial_sum(offsets.begin(), offsets.end(), offsets.begin());
  return offsets;
}

// Sets kDuplicate on every face (among those with no flag yet) whose vertex set,
// in either orientation, equals that of an earlier face.
void mark_duplicates(const std::vector<Triangle>& faces, std::size_t vertex_count, std::vector<std::uint8_t>& flags) {
  auto sorted = [](Triangle f) {
    std::sort(f.begin(), f.end());
    return f;
  };
  const std::vector<std::size_t> offsets = bucket_offsets(vertex_count, [&](auto count) {
    for (std::size_t f = 0; f < faces.size(); ++f) {
      if (flags[f] == 0) count(sorted(faces[f])[0]);
    }
  });
  struct Key {
    Index mid, high, face;
  };
  std::vector<Key> keys(offsets.back());
  std::vector<std::size_t> cursor(offsets.begin(), offsets.end() - 1);
  for (std::size_t f = 0; f < faces.size(); ++f) {
    if (flags[f] != 0) continue;
    const Triangle s = sorted(faces[f]);
    keys[cursor[s[0]]++] = {s[1], s[2], static_cast<Index>(f)};
  }
  for (std::size_t v = 0; v < vertex_count; ++v) {
    const auto begin = keys.begin() + offsets[v], end = keys.begin() + offsets[v + 1];
    std::sort(begin, end, [](const Key& a, const Key& b) {
      return std::tie(a.mid, a.high, a.face) < std::tie(b.mid, b.high, b.face);
    });
    for (auto it = begin; it != end && it + 1 != end; ++it) {
      if (it[1].mid == it[0].mid && it[1].high == it[0].high) flags[it[1].face] |= kDuplicate;
    }
  }
}

// Adds `faces` to `issue` in ascending order, so that `first` is the lowest.
void add_sorted(IssueCount& issue, std::vector<Index> faces) {
  std::sort(faces.begin(), faces.end());
  for (const Index f : faces) issue.add(f);
}

// Edge-based checks over the usable faces (flag 0): non-manifold edges and
// vertices, orientation, boundary edges and loops.
void analyze_edges(const TriMesh& mesh, const std::vector<std::uint8_t>& flags, ValidationReport& report) {
  const std::size_t n = mesh.vertex_count();
  const std::size_t m = mesh.face_count();
  // Half-edges bucketed by their lower vertex; `forward` when they run low -> high.
  struct HalfEdge {
    Index high;
    Index face;
    std::uint8_t corner;  // the half-edge starts at faces[face][corner]
    bool forward;
  };
  const std::vector<std::size_t> offsets = bucket_offsets(n, [&](auto count) {
    for (std::size_t f = 0; f < m; ++f) {
      if (flags[f] != 0) continue;
      const Triangle& t = mesh.faces[f];
      for (int k = 0; k < 3; ++k) count(std::min(t[k], t[(k + 1) % 3]));
    }
  });
  std::vector<HalfEdge> edges(offsets.back());
  {
    std::vector<std::size_t> cursor(offsets.begin(), offsets.end() - 1);
    for (std::size_t f = 0; f < m; ++f) {
      if (flags[f] != 0) continue;
      const Triangle& t = mesh.faces[f];
      for (int k = 0; k < 3; ++k) {
        const Index a = t[k], b = t[(k + 1) % 3];
        edges[cursor[std::min(a, b)]++] = {std::max(a, b), static_cast<Index>(f), static_cast<std::uint8_t>(k), a < b};
      }
    }
  }

  // Corners (3 * face + k) of one vertex are joined when their faces share an
  // edge at that vertex; each resulting set is one fan.
  DisjointSets corners(3 * m);
  auto corner_at = [](const HalfEdge& e, bool low_end) {
    const int local = (e.forward == low_end) ? e.corner : (e.corner + 1) % 3;
    return 3 * std::size_t{e.face} + static_cast<std::size_t>(local);
  };
  std::vector<Index> non_manifold_faces, inconsistent_faces;
  std::vector<std::pair<Index, Index>> boundary;  // directed as in their face
  for (std::size_t low = 0; low < n; ++low) {
    const auto begin = edges.begin() + offsets[low], end = edges.begin() + offsets[low + 1];
    std::sort(begin, end, [](const HalfEdge& a, const HalfEdge& b) {
      return std::tie(a.high, a.face, a.corner) < std::tie(b.high, b.face, b.corner);
    });
    for (auto group = begin; group != end;) {
      auto group_end = group + 1;
      while (group_end != end && group_end->high == group->high) ++group_end;
      const auto size = group_end - group;
      if (size == 1) {
        ++report.boundary_edges;
        const Index l = static_cast<Index>(low), h = group->high;
        boundary.push_back(group->forward ? std::pair{l, h} : std::pair{h, l});
      } else if (size == 2) {
        if (group[0].forward == group[1].forward) inconsistent_faces.push_back(group[0].face);
      } else {
        non_manifold_faces.push_back(group[0].face);  // lowest face on the edge
      }
      for (auto e = group + 1; e != group_end; ++e) {
        corners.unite(corner_at(*group, true), corner_at(*e, true));
        corners.unite(corner_at(*group, false), corner_at(*e, false));
      }
      group = group_end;
    }
  }
  add_sorted(report.non_manifold_edges, std::move(non_manifold_faces));
  add_sorted(report.inconsistent_orientation, std::move(inconsistent_faces));

  std::vector<std::uint32_t> fans(n, 0);
  for (std::size_t f = 0; f < m; ++f) {
    if (flags[f] != 0) continue;
    for (int k = 0; k < 3; ++k) {
      if (corners.find(3 * f + k) == 3 * f + k) ++fans[mesh.faces[f][k]];
    }
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (fans[v] > 1) report.non_manifold_vertices.add(static_cast<std::int64_t>(v));
  }

  // Boundary loops: follow outgoing boundary half-edges until back at the start.
  // On a manifold mesh each boundary vertex has exactly one; a walk that gets
  // stuck (only possible on broken meshes) is not counted as a loop.
  const std::vector<std::size_t> out_offsets = bucket_offsets(n, [&](auto count) {
    for (const auto& [from, to] : boundary) count(from);
  });
  std::vector<Index> targets(boundary.size());
  std::vector<std::size_t> next(out_offsets.begin(), out_offsets.end() - 1);
  for (const auto& [from, to] : boundary) targets[next[from]++] = to;
  std::copy(out_offsets.begin(), out_offsets.end() - 1, next.begin());
  for (std::size_t start = 0; start < n; ++start) {
    while (next[start] < out_offsets[start + 1]) {
      std::size_t at = start;
      while (next[at] < out_offsets[at + 1]) {
        at = targets[next[at]++];
        if (at == start) {
          ++report.boundary_loops;
          break;
        }
      }
    }
  }
}

struct Analysis {
  ValidationReport report;
  std::vector<std::uint8_t> face_flags;  // kOutOfRange / kDegenerate / kDuplicate; 0 = usable
};

Analysis analyze(const TriMesh& mesh) {
  Analysis analysis;
  ValidationReport& r = analysis.report;
  const std::size_t n = mesh.vertex_count();
  const std::size_t m = mesh.face_count();
  r.vertex_count = n;
  r.face_count = m;
  std::vector<std::uint8_t>& flags = analysis.face_flags;
  flags.assign(m, 0);

  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity());
  Vec3 hi = -lo;
  for (std::size_t v = 0; v < n; ++v) {
    const Vec3& p = mesh.positions[v];
    if (!p.allFinite()) {
      r.non_finite_vertices.add(static_cast<std::int64_t>(v));
    } else {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  }
  const double diagonal = lo.x() <= hi.x() ? (hi - lo).norm() : 0.0;
  const double zero_area = 1e-14 * diagonal * diagonal;

  for (std::size_t f = 0; f < m; ++f) {
    const Triangle& t = mesh.faces[f];
    if (t[0] >= n || t[1] >= n || t[2] >= n) {
      flags[f] = kOutOfRange;
      r.out_of_range_faces.add(static_cast<std::int64_t>(f));
    } else if (has_repeated_index(t)) {
      flags[f] = kDegenerate;
      r.degenerate_faces.add(static_cast<std::int64_t>(f));
    } else {
      const Vec3& a = mesh.positions[t[0]];
      const Vec3& b = mesh.positions[t[1]];
      const Vec3& c = mesh.positions[t[2]];
      if (a.allFinite() && b.allFinite() && c.allFinite() && 0.5 * (b - a).cross(c - a).norm() <= zero_area) {
        r.zero_area_faces.add(static_cast<std::int64_t>(f));
      }
    }
  }
  mark_duplicates(mesh.faces, n, flags);
  for (std::size_t f = 0; f < m; ++f) {
    if (flags[f] & kDuplicate) r.duplicate_faces.add(static_cast<std::int64_t>(f));
  }

  std::vector<bool> referenced(n, false);
  DisjointSets components(n);
  std::vector<std::uint32_t> faces_at(n, 0);
  for (std::size_t f = 0; f < m; ++f) {
    if (flags[f] != 0) continue;
    const Triangle& t = mesh.faces[f];
    for (const Index v : t) referenced[v] = true, ++faces_at[v];
    components.unite(t[0], t[1]);
    components.unite(t[0], t[2]);
  }
  for (std::size_t v = 0; v < n; ++v) {
    if (faces_at[v] > kMaxFacesAtVertex) r.crowded_vertices.add(static_cast<std::int64_t>(v));
    if (!referenced[v]) r.unreferenced_vertices.add(static_cast<std::int64_t>(v));
    else if (components.find(v) == v) ++r.components;
  }

  analyze_edges(mesh, flags, r);
  return analysis;
}

std::string plural(std::size_t count, const char* singular, const char* plural_form) {
  return std::to_string(count) + " " + (count == 1 ? singular : plural_form);
}

std::string first_of(const IssueCount& issue, const char* kind) {
  return "(first: " + std::string(kind) + " " + std::to_string(issue.first) + ")";
}

std::string first_at(const IssueCount& issue) { return "(first at face " + std::to_string(issue.first) + ")"; }

[[noreturn]] void unusable(const std::string& reason, const ValidationReport& report) {
  throw InvalidMeshError("mesh is not usable: " + reason + "\n" + report.to_string());
}

// Why a mesh that passed the input checks is still fatal after repair.
std::string fatal_reason(const ValidationReport& r) {
  if (r.face_count == 0) return "no usable faces (every face is degenerate or a duplicate)";
  if (r.non_manifold_edges.count) {
    return "non-manifold: " + plural(r.non_manifold_edges.count, "edge has", "edges have") +
           " more than two faces " + first_at(r.non_manifold_edges);
  }
  if (r.non_manifold_vertices.count) {
    return "non-manifold: " + plural(r.non_manifold_vertices.count, "vertex joins", "vertices join") +
           " separate surface sheets " + first_of(r.non_manifold_vertices, "vertex");
  }
  if (r.crowded_vertices.count) {
    return plural(r.crowded_vertices.count, "vertex is", "vertices are") + " in more than " +
           std::to_string(kMaxFacesAtVertex) + " faces, the most one vertex may be in " +
           first_of(r.crowded_vertices, "vertex") +
           "; a polygon of many corners fan-triangulated makes one: triangulate it evenly before the upload";
  }
  return "inconsistent orientation: " +
         plural(r.inconsistent_orientation.count, "edge is", "edges are") +
         " used twice in the same direction " + first_at(r.inconsistent_orientation);
}

// Vertex indices within `tolerance` of a lower-indexed vertex map to the lowest
// such vertex (greedy: only unmerged vertices attract others); others map to
// themselves. Only vertices referenced by `faces` take part.
std::vector<Index> weld_targets(const std::vector<Vec3>& positions, const std::vector<Triangle>& faces,
                                double tolerance) {
  const std::size_t n = positions.size();
  std::vector<Index> target(n);
  std::iota(target.begin(), target.end(), Index{0});
  std::vector<bool> referenced(n, false);
  for (const Triangle& f : faces) {
    for (const Index v : f) referenced[v] = true;
  }

  using Cell = std::array<std::int64_t, 3>;
  struct CellHash {
    std::size_t operator()(const Cell& c) const noexcept {
      std::uint64_t h = 0;
      for (const std::int64_t x : c) h = (h ^ static_cast<std::uint64_t>(x)) * 0x9E3779B97F4A7C15ull + (h >> 29);
      return static_cast<std::size_t>(h);
    }
  };
  // With tolerance 0 a "cell" is an exact position (+0.0 added so that -0.0
  // and 0.0 coincide); otherwise a cube of side `tolerance`, clamped so that
  // neighbour arithmetic cannot overflow.
  auto cell_of = [tolerance](const Vec3& p) {
    Cell c;
    for (int k = 0; k < 3; ++k) {
      if (tolerance == 0.0) {
        c[k] = std::bit_cast<std::int64_t>(p[k] + 0.0);
      } else {
        constexpr double kLimit = 4.0e18;
        c[k] = static_cast<std::int64_t>(std::clamp(std::floor(p[k] / tolerance), -kLimit, kLimit));
      }
    }
    return c;
  };
  std::unordered_map<Cell, Index, CellHash> head;  // cell -> latest representative in it
  head.reserve(n);
  std::vector<Index> next_in_cell(n, kNone);
  for (std::size_t v = 0; v < n; ++v) {
    if (!referenced[v]) continue;
    const Vec3& p = positions[v];
    const Cell cell = cell_of(p);
    if (tolerance == 0.0) {
      const auto [it, inserted] = head.try_emplace(cell, static_cast<Index>(v));
      if (!inserted) target[v] = it->second;
      continue;
    }
    Index best = kNone;
    for (std::int64_t dx = -1; dx <= 1; ++dx) {
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        for (std::int64_t dz = -1; dz <= 1; ++dz) {
          const auto it = head.find({cell[0] + dx, cell[1] + dy, cell[2] + dz});
          if (it == head.end()) continue;
          for (Index w = it->second; w != kNone; w = next_in_cell[w]) {
            if (w < best && (positions[w] - p).norm() <= tolerance) best = w;
          }
        }
      }
    }
    if (best != kNone) {
      target[v] = best;
    } else {
      const auto [it, inserted] = head.try_emplace(cell, static_cast<Index>(v));
      if (!inserted) {
        next_in_cell[v] = it->second;
        it->second = static_cast<Index>(v);
      }
    }
  }
  return target;
}

}  // namespace

bool ValidationReport::fatal() const {
  // The face classes are disjoint: a face is counted in at most one of them.
  const std::size_t usable_faces =
      face_count - out_of_range_faces.count - degenerate_faces.count - duplicate_faces.count;
  return vertex_count == 0 || usable_faces == 0 || non_finite_vertices.count || out_of_range_faces.count ||
         non_manifold_edges.count || non_manifold_vertices.count || inconsistent_orientation.count ||
         crowded_vertices.count;
}

bool ValidationReport::repairable() const {
  return degenerate_faces.count || duplicate_faces.count || unreferenced_vertices.count;
}

std::string ValidationReport::to_string() const {
  std::vector<std::string> lines;
  auto count_line = [&](const char* label, std::size_t value) {
    if (value) lines.push_back(std::string(label) + ": " + std::to_string(value));
  };
  auto issue_line = [&](const char* label, const IssueCount& issue, const std::string& first) {
    if (issue.count) lines.push_back(std::string(label) + ": " + std::to_string(issue.count) + " " + first);
  };
  count_line("vertices", vertex_count);
  count_line("faces", face_count);
  issue_line("non-finite vertices", non_finite_vertices, first_of(non_finite_vertices, "vertex"));
  issue_line("out-of-range faces", out_of_range_faces, first_of(out_of_range_faces, "face"));
  issue_line("degenerate faces", degenerate_faces, first_of(degenerate_faces, "face"));
  issue_line("zero-area faces", zero_area_faces, first_of(zero_area_faces, "face"));
  issue_line("duplicate faces", duplicate_faces, first_of(duplicate_faces, "face"));
  issue_line("unreferenced vertices", unreferenced_vertices, first_of(unreferenced_vertices, "vertex"));
  issue_line("non-manifold edges", non_manifold_edges, first_at(non_manifold_edges));
  const std::string crowded = "vertices in more than " + std::to_string(kMaxFacesAtVertex) + " faces";
  issue_line(crowded.c_str(), crowded_vertices, first_of(crowded_vertices, "vertex"));
  issue_line("non-manifold vertices", non_manifold_vertices, first_of(non_manifold_vertices, "vertex"));
  issue_line("inconsistently oriented edges", inconsistent_orientation, first_at(inconsistent_orientation));
  count_line("components", components);
  count_line("boundary loops", boundary_loops);
  count_line("boundary edges", boundary_edges);
  std::string out;
  for (const std::string& line : lines) out += (out.empty() ? "" : "\n") + line;
  return out;
}

ValidationReport validate_mesh(const TriMesh& mesh) { return analyze(mesh).report; }

bool RepairReport::changed() const {
  return removed_degenerate_faces || removed_duplicate_faces || removed_unreferenced_vertices || welded_vertices;
}

std::string RepairReport::to_string() const {
  if (!changed()) return "no changes";
  std::vector<std::string> lines;
  auto line = [&](const char* label, std::size_t value) {
    if (value) lines.push_back(std::string(label) + ": " + std::to_string(value));
  };
  line("removed degenerate faces", removed_degenerate_faces);
  line("removed duplicate faces", removed_duplicate_faces);
  line("removed unreferenced vertices", removed_unreferenced_vertices);
  line("welded vertices", welded_vertices);
  std::string out;
  for (const std::string& l : lines) out += (out.empty() ? "" : "\n") + l;
  return out;
}

TriMesh repair_mesh(const TriMesh& mesh, const RepairOptions& options, RepairReport* report) {
  if (options.weld_coincident && !(options.weld_tolerance >= 0.0 && std::isfinite(options.weld_tolerance))) {
    throw std::invalid_argument("repair_mesh: weld_tolerance must be finite and >= 0");
  }
  RepairReport local_report;
  RepairReport& changes = report ? *report : local_report;
  changes = RepairReport{};

  // Problems no repair can fix are judged on the mesh as given, before
  // anything is dropped or renumbered.
  const Analysis input = analyze(mesh);
  const ValidationReport& in = input.report;
  const std::size_t n = mesh.vertex_count();
  if (n == 0 || mesh.face_count() == 0) {
    unusable("empty (" + plural(n, "vertex", "vertices") + ", " + plural(mesh.face_count(), "face", "faces") + ")",
             in);
  }
  if (in.non_finite_vertices.count) {
    unusable(plural(in.non_finite_vertices.count, "vertex has", "vertices have") + " NaN/Inf coordinates " +
                 first_of(in.non_finite_vertices, "vertex"),
             in);
  }
  if (in.out_of_range_faces.count) {
    const Triangle& f = mesh.faces[in.out_of_range_faces.first];
    const Index bad = *std::find_if(f.begin(), f.end(), [n](Index i) { return i >= n; });
    unusable(plural(in.out_of_range_faces.count, "face indexes", "faces index") + " vertices out of range (first: face " +
                 std::to_string(in.out_of_range_faces.first) + ", index " + std::to_string(bad) +
                 " >= " + plural(n, "vertex", "vertices") + ")",
             in);
  }

  std::vector<Triangle> faces;
  std::vector<Index> face_origin;  // kept face -> input face
  faces.reserve(mesh.face_count());
  face_origin.reserve(mesh.face_count());
  for (std::size_t f = 0; f < mesh.face_count(); ++f) {
    const std::uint8_t flag = input.face_flags[f];
    if (flag == 0) {
      faces.push_back(mesh.faces[f]);
      face_origin.push_back(static_cast<Index>(f));
    } else if (flag & kDegenerate) {
      ++changes.removed_degenerate_faces;
    } else {
      ++changes.removed_duplicate_faces;
    }
  }

  if (options.weld_coincident) {
    const std::vector<Index> target = weld_targets(mesh.positions, faces, options.weld_tolerance);
    for (std::size_t v = 0; v < n; ++v) changes.welded_vertices += target[v] != v;
    for (Triangle& f : faces) {
      for (Index& v : f) v = target[v];
    }
    // Welding can collapse faces or make two faces coincide.
    std::vector<std::uint8_t> flags(faces.size(), 0);
    for (std::size_t f = 0; f < faces.size(); ++f) {
      if (has_repeated_index(faces[f])) flags[f] = kDegenerate;
    }
    mark_duplicates(faces, n, flags);
    std::size_t kept = 0;
    for (std::size_t f = 0; f < faces.size(); ++f) {
      if (flags[f] == 0) {
        faces[kept] = faces[f];
        face_origin[kept] = face_origin[f];
        ++kept;
      } else if (flags[f] & kDegenerate) {
        ++changes.removed_degenerate_faces;
      } else {
        ++changes.removed_duplicate_faces;
      }
    }
    faces.resize(kept);
    face_origin.resize(kept);
  }

  // Drop unreferenced vertices, keeping the relative order of the others.
  std::vector<Index> old_to_new(n, kNone);
  for (const Triangle& f : faces) {
    for (const Index v : f) old_to_new[v] = 0;
  }
  TriMesh result;
  for (std::size_t v = 0; v < n; ++v) {
    if (old_to_new[v] == kNone) continue;
    old_to_new[v] = static_cast<Index>(result.positions.size());
    result.positions.push_back(mesh.positions[v]);
    changes.new_to_old_vertex.push_back(static_cast<Index>(v));
  }
  changes.removed_unreferenced_vertices = n - result.vertex_count() - changes.welded_vertices;
  result.faces = std::move(faces);
  for (Triangle& f : result.faces) {
    for (Index& v : f) v = old_to_new[v];
  }
  changes.new_to_old_face = std::move(face_origin);

  ValidationReport out = validate_mesh(result);
  if (out.fatal()) {
    // Report indices in the numbering of the mesh as given.
    for (IssueCount* issue : {&out.zero_area_faces, &out.non_manifold_edges, &out.inconsistent_orientation}) {
      if (issue->count) issue->first = changes.new_to_old_face[issue->first];
    }
    for (IssueCount* issue : {&out.non_manifold_vertices, &out.unreferenced_vertices}) {
      if (issue->count) issue->first = changes.new_to_old_vertex[issue->first];
    }
    unusable(fatal_reason(out), out);
  }
  return result;
}

}  // namespace filigree
