#include "preprocess/simplifier.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <queue>

#include <Eigen/Geometry>

#include "geometry/ring_frame.h"
#include "geometry/ring_weights.h"
#include "geometry/triangle_geometry.h"
#include "hierarchy/hierarchy.h"
#include "preprocess/conformal_ring_map.h"
#include "preprocess/dynamic_mesh.h"
#include "preprocess/polygon_triangulation.h"
#include "util/parallel_for.h"

namespace filigree {
namespace {

// Holes with more corners than this are not triangulated (rare, and the
// quadratic ear search would dominate).
constexpr std::size_t kMaxRing = 32;
// Parameterised points per removed face that the cost looks at; the removal
// itself re-locates all of them.
constexpr std::size_t kCostSamplesPerFace = 8;

// A candidate removal: the ring, its flattening and the hole's triangulation.
struct Plan {
  VertexRing ring;
  std::vector<Vec2> uv;
  std::vector<std::array<int, 3>> tris;
  double cost = 0.0;
};

// A point's place in the new triangulation: triangle index and barycentrics.
struct Location {
  int tri = 0;
  Vec3 bary;
};

Location locate(const Vec2& q, const std::vector<Vec2>& uv, const std::vector<std::array<int, 3>>& tris) {
  Location best{-1, Vec3::Zero()};
  double best_min = -std::numeric_limits<double>::infinity();
  for (int t = 0; t < static_cast<int>(tris.size()); ++t) {
    const Vec2 &a = uv[tris[t][0]], &b = uv[tris[t][1]], &c = uv[tris[t][2]];
    const double det = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
    const double l1 = ((q - a).x() * (c - a).y() - (q - a).y() * (c - a).x()) / det;
    const double l2 = ((b - a).x() * (q - a).y() - (b - a).y() * (q - a).x()) / det;
    const Vec3 bary(1.0 - l1 - l2, l1, l2);
    if (bary.minCoeff() > best_min) best_min = bary.minCoeff(), best = {t, bary};
  }
  // Numerically outside every triangle (by rounding): clamp into the closest.
  best.bary = best.bary.cwiseMax(0.0);
  best.bary /= best.bary.sum();
  return best;
}

class Simplifier {
 public:
  Simplifier(const TriMesh& mesh, const std::vector<double>& curvature, const std::vector<double>& saliency,
             const SimplifyOptions& options, Hierarchy& out)
      : opt_(options), mesh_(mesh), saliency_(saliency), out_(out) {
    const std::size_t n = mesh.positions.size();
    diag_ = std::max(bounding_box_diagonal(mesh.positions), 1e-300);
    // Curvature made dimensionless by the mean edge length, then scaled by its
    // 90th percentile so curvature_weight means the same on every mesh.
    double mean_edge = 0.0;
    for (const Triangle& f : mesh.faces) mean_edge += (mesh.positions[f[0]] - mesh.positions[f[1]]).norm();
    mean_edge /= static_cast<double>(std::max<std::size_t>(mesh.faces.size(), 1));
    curvature_.resize(n);
    for (std::size_t i = 0; i < n; ++i) curvature_[i] = curvature[i] * mean_edge;
    std::vector<double> sorted = curvature_;
    const std::size_t k90 = sorted.size() * 9 / 10;
    std::nth_element(sorted.begin(), sorted.begin() + k90, sorted.end());
    const double p90 = sorted.empty() ? 0.0 : sorted[k90];
    for (double& c : curvature_) c = p90 > 0.0 ? std::min(c / p90, 3.0) : 0.0;

    face_points_.resize(mesh.faces.size());
    point_face_.assign(n, kNone);
    point_bary_.assign(n, Vec3::Zero());
    removed_.assign(n, false);
    out_.original_faces = mesh.faces;  // face ids: the input's, then add_face's
  }

  void run() {
    const std::size_t n = mesh_.positions().size();
    const std::size_t target = std::max<std::size_t>(opt_.target_vertices, 1);
    out_.ring_offsets = {0};

    // Initial costs in parallel; each thread plans with its own scratch.
    std::vector<double> initial(n);
    parallel_for(n, opt_.threads, [&](std::size_t v) {
      thread_local Plan scratch;
      initial[v] = plan(static_cast<Index>(v), scratch) ? scratch.cost : -1.0;
    });

    struct Entry {
      double cost;
      Index v;
      std::uint32_t version;
    };
    auto later = [](const Entry& a, const Entry& b) { return a.cost != b.cost ? a.cost > b.cost : a.v > b.v; };
    std::priority_queue<Entry, std::vector<Entry>, decltype(later)> heap(later);
    std::vector<std::uint32_t> version(n, 0);
    std::vector<bool> dirty(n, false), queued(n, false);
    for (Index v = 0; v < n; ++v)
      if (initial[v] >= 0.0) heap.push({initial[v], v, 0}), queued[v] = true;

    std::size_t remaining = n;
    const std::size_t to_remove = n > target ? n - target : 0;
    std::size_t next_report = 0;
    Plan p;
    // The queue ran dry above the target: a removal that a change two rings
    // away made valid (a diagonal no longer an edge, a neighbour's valence)
    // was never queued again. Look at every vertex left once more; false if
    // none can go.
    const auto queue_what_is_left = [&] {
      bool any = false;
      for (Index v = 0; v < n; ++v) {
        if (removed_[v] || queued[v] || !plan(v, p)) continue;
        heap.push({p.cost, v, ++version[v]});
        queued[v] = true;
        dirty[v] = false;
        any = true;
      }
      return any;
    };
    while (remaining > target) {
      if (heap.empty() && !queue_what_is_left()) break;
      if (opt_.stop && opt_.stop->load(std::memory_order_relaxed)) throw PreprocessingStopped();
      const Entry e = heap.top();
      heap.pop();
      const Index v = e.v;
      if (removed_[v] || e.version != version[v]) continue;
      queued[v] = false;
      // Lazy update (thesis §3.1.1): a vertex whose neighbourhood changed is
      // re-costed only when it reaches the top; it stays out of the queue while
      // its removal is invalid, until a neighbour's removal changes that.
      if (!plan(v, p)) {
        dirty[v] = false;
        continue;
      }
      if (dirty[v]) {
        dirty[v] = false;
        if (!heap.empty() && p.cost > heap.top().cost) {
          heap.push({p.cost, v, ++version[v]});
          queued[v] = true;
          continue;
        }
      }
      perform(v, p);
      --remaining;
      for (Index j : p.ring.ring) {
        dirty[j] = true;
        if (!queued[j]) heap.push({e.cost, j, ++version[j]}), queued[j] = true;
      }
      const std::size_t done = n - remaining;
      if (opt_.progress && done >= next_report) {
        opt_.progress(static_cast<double>(done) / static_cast<double>(std::max<std::size_t>(to_remove, 1)));
        next_report = done + std::max<std::size_t>(to_remove / 200, 1);
      }
    }
    if (opt_.report && remaining > target) {
      // Why every vertex left stays: what a larger base than asked is made of.
      opt_.report->refused.fill(0);
      Plan scratch;
      for (Index v = 0; v < n; ++v) {
        BaseRefusal why = BaseRefusal::kTopology;
        if (!removed_[v] && !plan(v, scratch, &why)) ++opt_.report->refused[static_cast<std::size_t>(why)];
      }
    }
    finish();
    if (opt_.progress) opt_.progress(1.0);
  }

 private:
  // Plans the removal of v; false if it would break manifoldness, topology,
  // the boundary, flip or produce poor triangles.
  // `why`, when given, says which check refused (set only on refusal).
  bool plan(Index v, Plan& p, BaseRefusal* why = nullptr) const {
    const auto refuse = [why](BaseRefusal r) {
      if (why) *why = r;
      return false;
    };
    const auto& x = mesh_.positions();
    // Before the ring is ordered (quadratic in the valence): a hub of
    // thousands of faces (a fan-triangulated polygon) is refused at once.
    if (mesh_.valence(v) > kMaxRing) return refuse(BaseRefusal::kValence);
    if (!mesh_.ring(v, p.ring)) return refuse(BaseRefusal::kTopology);
    const std::vector<Index>& r = p.ring.ring;
    const std::size_t k = r.size();
    const bool closed = p.ring.closed;
    if (k < 3) return refuse(BaseRefusal::kTopology);  // (k ≤ kMaxRing: the valence was checked)
    if (!closed) {
      const double turn = std::numbers::pi - angle_at(x[v], x[r[0]], x[r[k - 1]]);
      if (turn > opt_.max_boundary_turn_deg * std::numbers::pi / 180.0) return refuse(BaseRefusal::kBoundary);
      if (mesh_.has_edge(r[0], r[k - 1])) return refuse(BaseRefusal::kBoundary);  // would close the boundary loop
    }
    p.uv = conformal_ring_map(x[v], r, x, closed);
    if (p.uv.empty()) return refuse(BaseRefusal::kShape);
    p.tris = triangulate_polygon(p.uv);
    if (p.tris.empty()) return refuse(BaseRefusal::kShape);

    // Manifoldness: every diagonal must be a new edge, and every ring vertex
    // must keep valence ≥ 3 (≥ 2 on the boundary); the latter also rejects
    // collapsing a tetrahedron into a doubled triangle.
    std::array<int, kMaxRing> gained{};
    if (!closed) ++gained[0], ++gained[k - 1];
    for (const auto& t : p.tris) {
      for (int c = 0; c < 3; ++c) {
        const int a = t[c], b = t[(c + 1) % 3];
        if (a > b) continue;  // each diagonal appears in two triangles; count it once
        const bool ring_edge = b == a + 1 || (closed && a == 0 && b == static_cast<int>(k) - 1);
        if (ring_edge || (!closed && a == 0 && b == static_cast<int>(k) - 1)) continue;
        if (mesh_.has_edge(r[a], r[b])) return refuse(BaseRefusal::kTopology);
        ++gained[a], ++gained[b];
      }
    }
    for (std::size_t i = 0; i < k; ++i) {
      const std::size_t valence = mesh_.valence(r[i]) - 1 + gained[i];
      if (valence < (mesh_.is_boundary(r[i]) ? 2u : 3u)) return refuse(BaseRefusal::kTopology);
    }

    // Geometry: no flips, no needles/caps worse than what was there.
    Vec3 fan_normal = Vec3::Zero();
    double worst_old = 1.0, spoke = 0.0;
    for (FaceId f : p.ring.fan) {
      const Triangle& t = mesh_.face(f);
      fan_normal += triangle_area_vector(x[t[0]], x[t[1]], x[t[2]]);
      worst_old = std::min(worst_old, triangle_quality(x[t[0]], x[t[1]], x[t[2]]));
    }
    for (Index j : r) spoke += (x[j] - x[v]).norm() / static_cast<double>(k);
    const double fan_len = fan_normal.norm();
    const double min_quality = std::min(opt_.min_triangle_quality, worst_old);
    const double cos_max = std::cos(opt_.max_normal_change_deg * std::numbers::pi / 180.0);
    for (const auto& t : p.tris) {
      const Vec3 &a = x[r[t[0]]], &b = x[r[t[1]]], &c = x[r[t[2]]];
      const Vec3 n = triangle_area_vector(a, b, c);
      if (!(n.norm() > 0.0) || triangle_quality(a, b, c) < min_quality) return refuse(BaseRefusal::kShape);
      if (fan_len > 0.0 && n.dot(fan_normal) < cos_max * n.norm() * fan_len) return refuse(BaseRefusal::kNormal);
    }

    // Error: how far v and the points parameterised in its fan would end up
    // from their true positions on the coarser mesh.
    double error = (image(p, locate(Vec2::Zero(), p.uv, p.tris)) - x[v]).norm();
    for (std::size_t i = 0; i < p.ring.fan.size(); ++i) {
      const std::vector<Index>& pts = face_points_[p.ring.fan[i]];
      const std::size_t stride = std::max<std::size_t>(pts.size() / kCostSamplesPerFace, 1);
      for (std::size_t s = 0; s < pts.size(); s += stride) {
        const Index q = pts[s];
        error = std::max(error, (image(p, locate(fan_uv(p, i, q), p.uv, p.tris)) - x[q]).norm());
      }
    }
    p.cost = (error / diag_ + opt_.size_weight * spoke / diag_) * (1.0 + opt_.saliency_weight * saliency_[v]) /
             (1.0 + opt_.curvature_weight * curvature_[v]);
    return true;
  }

  // 3D point of a location in the planned triangulation.
  Vec3 image(const Plan& p, const Location& l) const {
    const auto& x = mesh_.positions();
    const auto& t = p.tris[l.tri];
    return l.bary[0] * x[p.ring.ring[t[0]]] + l.bary[1] * x[p.ring.ring[t[1]]] + l.bary[2] * x[p.ring.ring[t[2]]];
  }

  // Planar position of point q, parameterised in fan face i, under the ring map:
  // the removed vertex maps to the origin, ring vertices to their uv.
  Vec2 fan_uv(const Plan& p, std::size_t i, Index q) const {
    const Triangle& t = mesh_.face(p.ring.fan[i]);
    const std::size_t k = p.ring.ring.size();
    Vec2 uv = Vec2::Zero();
    for (int c = 0; c < 3; ++c) {
      if (t[c] == p.ring.ring[i])
        uv += point_bary_[q][c] * p.uv[i];
      else if (t[c] == p.ring.ring[(i + 1) % k])
        uv += point_bary_[q][c] * p.uv[(i + 1) % k];
    }
    return uv;
  }

  void perform(Index v, const Plan& p) {
    const auto& x = mesh_.positions();
    const std::vector<Index>& r = p.ring.ring;

    // Ring coordinates for direct recovery (thesis eq. 3.10). The hierarchy
    // keeps the weights in 16-bit fixed point: round them first and compute
    // the offset in the frame of the rounded weights, so that the stored pair
    // puts v back where it was (only the offset's own float rounding remains).
    const std::vector<std::uint16_t> stored = quantize_ring_weights(ring_weights(x[v], r, x, p.ring.closed));
    out_.ring_weights.insert_back(stored.begin(), stored.end());
    out_.node_vertex.push_back(v);
    out_.node_closed.push_back(p.ring.closed ? 1 : 0);
    out_.ring_vertices.insert_back(r.begin(), r.end());
    out_.ring_offsets.push_back(static_cast<Index>(out_.ring_vertices.size()));
    out_.node_offset.push_back(ring_frame(r, std::span<const std::uint16_t>(stored), x, p.ring.closed).to_local(x[v]).cast<float>());

    // Faces: the fan dies, the hole's triangulation is born. Which faces
    // died, and so the dependency edges, are derived (hierarchy/node_graph.h).
    std::vector<FaceId> created;
    for (const auto& t : p.tris) {
      created.push_back(mesh_.add_face({r[t[0]], r[t[1]], r[t[2]]}));
      // Ring corners, as the hierarchy keeps created faces (a ring has ≤ kMaxRingSize vertices).
      out_.created_corners.push_back({static_cast<std::uint8_t>(t[0]), static_cast<std::uint8_t>(t[1]), static_cast<std::uint8_t>(t[2])});
      face_points_.emplace_back();
    }

    // MAPS: v and every point in its fan move into the new triangles through
    // the same planar map (thesis §3.1.2).
    auto place = [&](Index q, const Vec2& uv) {
      const Location l = locate(uv, p.uv, p.tris);
      const FaceId f = created[l.tri];
      point_face_[q] = f;
      point_bary_[q] = l.bary;
      face_points_[f].push_back(q);
    };
    place(v, Vec2::Zero());
    for (std::size_t i = 0; i < p.ring.fan.size(); ++i) {
      for (Index q : face_points_[p.ring.fan[i]]) place(q, fan_uv(p, i, q));
      std::vector<Index>().swap(face_points_[p.ring.fan[i]]);
    }
    for (FaceId f : p.ring.fan) mesh_.kill_face(f);
    removed_[v] = true;
  }

  // Base mesh and MAPS coordinates relative to it.
  void finish() {
    const std::size_t n = mesh_.positions().size();
    out_.base_vertices.clear();
    for (Index v = 0; v < n; ++v)
      if (!removed_[v]) out_.base_vertices.push_back(v);
    std::vector<Index> base_index(mesh_.face_count_ever(), kNone);
    out_.base_faces.clear();
    for (FaceId f = 0; f < mesh_.face_count_ever(); ++f) {
      if (!mesh_.face_alive(f)) continue;
      base_index[f] = static_cast<Index>(out_.base_faces.size());
      out_.base_faces.push_back(f);
    }
    std::vector<Index> maps_face(n, kNone);
    std::vector<Barycentric16> maps_bary(n);
    for (Index v = 0; v < n; ++v) {
      if (removed_[v]) {
        maps_face[v] = base_index[point_face_[v]];
        maps_bary[v] = quantize_barycentric(point_bary_[v]);
      } else {
        // A base vertex is the corner of its first live face.
        const FaceId f = mesh_.vertex_faces(v).front();
        const Triangle& t = mesh_.face(f);
        maps_face[v] = base_index[f];
        maps_bary[v] = quantize_barycentric(Vec3(t[0] == v, t[1] == v, t[2] == v));
      }
    }
    out_.maps_face = std::move(maps_face);
    out_.maps_bary = std::move(maps_bary);
  }

  const SimplifyOptions& opt_;
  DynamicMesh mesh_;
  const std::vector<double>& saliency_;
  Hierarchy& out_;
  double diag_ = 1.0;
  std::vector<double> curvature_;
  std::vector<std::vector<Index>> face_points_;  // per face: removed vertices parameterised in it
  std::vector<FaceId> point_face_;               // per removed vertex: its current face
  std::vector<Vec3> point_bary_;                 // ... and barycentrics in it
  std::vector<bool> removed_;
};

}  // namespace

const char* describe(BaseRefusal why) {
  switch (why) {
    case BaseRefusal::kTopology: return "would change the topology or break the manifold";
    case BaseRefusal::kValence: return "have more than 32 neighbours";
    case BaseRefusal::kBoundary: return "hold a boundary's shape";
    case BaseRefusal::kShape: return "would leave triangles of poor shape";
    case BaseRefusal::kNormal: return "would turn triangles too far";
  }
  return "?";
}

void simplify(const TriMesh& mesh, const std::vector<double>& curvature, const std::vector<double>& saliency,
              const SimplifyOptions& options, Hierarchy& out) {
  Simplifier(mesh, curvature, saliency, options, out).run();
}

}  // namespace filigree
