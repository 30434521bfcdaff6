#include "preprocess/simplifier.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <limits>

#include <Eigen/Geometry>

#include "geometry/ring_frame.h"
#include "geometry/ring_weights.h"
#include "geometry/triangle_geometry.h"
#include "hierarchy/hierarchy.h"
#include "mesh/vertex_order.h"
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
// A window holds the cheapest 1/kWindowShare of the candidates, at least
// kMinWindow (with 256, the last rounds of a small mesh took most of what
// was left at once, and its MAPS map drifted by 0.75 base edges against
// 0.37) and at most kMaxWindow (a round keeps a plan per window entry).
constexpr std::size_t kWindowShare = 8;
constexpr std::size_t kMinWindow = 16;
constexpr std::size_t kMaxWindow = std::size_t{1} << 15;
// Candidates sampled to find the window's cost bound.
constexpr std::size_t kPivotSample = 4096;

// A candidate removal: the ring, its flattening and the hole's triangulation.
struct Plan {
  VertexRing ring;
  std::vector<Vec2> uv;
  std::vector<std::array<int, 3>> tris;
  double cost = 0.0;
};

// What a plan checks and computes. The topology checks (has the mesh each
// diagonal already, ring valences) read the ring's neighbours' faces, the
// slowest part of a plan, and rarely refuse: a candidate's cost is planned
// without them, and a removal checks them once chosen.
enum class PlanWork : std::uint8_t {
  kFull,      // every check, and the cost
  kCostOnly,  // the cost, without the topology checks
  kNoCost,    // every check; p.cost left as it is (the caller knows it)
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

// Runs fn(i) for i in [0, count) on up to `threads` threads (contiguous
// ranges, so results written per index do not depend on the thread count),
// throwing PreprocessingStopped soon after `stop` turns true.
template <class Fn>
void parallel_steps(std::size_t count, int threads, const std::atomic<bool>* stop, Fn&& fn) {
  constexpr std::size_t kCheckEvery = 32, kMinPerThread = 64;
  const std::size_t parts = std::clamp<std::size_t>(count / kMinPerThread, 1, std::max(threads, 1));
  parallel_ranges(count, parts, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      if ((i - begin) % kCheckEvery == 0 && stop && stop->load(std::memory_order_relaxed)) throw PreprocessingStopped();
      fn(i);
    }
  });
}

// Removal by rounds (DESIGN §2.1): a window holds the cheapest candidates
// by their last known cost (as the thesis' lazy queue orders them, §3.1.1);
// each round plans its stale ones again and removes those no dearer than
// any candidate outside the window that are the cheapest of all candidates
// within two edges of themselves, as the one-at-a-time queue would take
// them. Their closed 1-rings are disjoint, so they touch disjoint faces,
// points and incidences: planning and removing run on all threads, and the
// result depends only on the mesh and the options, the same hierarchy, byte
// for byte, for any thread count. With a window of one candidate it is the
// queue (the elephant's base the same 262 vertices, its quality row within
// 0.2%: float barycentrics move the costs in their last bits).
class Simplifier {
 public:
  // `traits` is read here and freed by the caller's move.
  Simplifier(const TriMesh& mesh, VertexTraits& traits, const SimplifyOptions& options, Hierarchy& out)
      : opt_(options),
        original_faces_(mesh.faces),
        order_(locality_order(mesh.positions)),
        local_(permute_vertices(mesh, order_)),
        mesh_(local_, permuted(traits.boundary)),
        saliency_(permuted(traits.saliency)),
        out_(out) {
    const std::size_t n = mesh.positions.size();
    std::vector<Triangle>().swap(local_.faces);  // mesh_ has its own copy; positions it reads from local_
    const std::vector<double>& curvature = traits.curvature;
    diag_ = std::max(bounding_box_diagonal(mesh.positions), 1e-300);
    // Curvature made dimensionless by the mean edge length, then scaled by its
    // 90th percentile so curvature_weight means the same on every mesh.
    double mean_edge = 0.0;
    for (const Triangle& f : mesh.faces) mean_edge += (mesh.positions[f[0]] - mesh.positions[f[1]]).norm();
    mean_edge /= static_cast<double>(std::max<std::size_t>(mesh.faces.size(), 1));
    curvature_.resize(n);
    for (std::size_t i = 0; i < n; ++i) curvature_[i] = curvature[order_[i]] * mean_edge;
    std::vector<double> sorted = curvature_;
    const std::size_t k90 = sorted.size() * 9 / 10;
    std::nth_element(sorted.begin(), sorted.begin() + k90, sorted.end());
    const double p90 = sorted.empty() ? 0.0 : sorted[k90];
    for (double& c : curvature_) c = p90 > 0.0 ? std::min(c / p90, 3.0) : 0.0;

    // A removal of valence k creates k − 2 faces: ~4–5 on average.
    const std::size_t target = std::max<std::size_t>(opt_.target_vertices, 1);
    const std::size_t faces_ever = mesh.faces.size() + 5 * (n > target ? n - target : 0);
    mesh_.reserve(faces_ever);
    face_points_at_.reserve(faces_ever);
    face_point_count_.reserve(faces_ever);
    face_points_at_.assign(mesh.faces.size(), 0);
    face_point_count_.assign(mesh.faces.size(), 0);
    // Arena offsets are 32-bit; compaction keeps the arena under ~3n.
    if (n >= (std::size_t{1} << 29)) throw std::invalid_argument("mesh too large to simplify: 2^29 vertices or more");
    point_face_.assign(n, kNone);
    point_bary_.assign(n, PointBary{0.0f, 0.0f});
    removed_.assign(n, 0);
    traits = VertexTraits{};  // permuted copies made
  }

  void run() {
    const std::size_t n = mesh_.positions().size();
    const std::size_t target = std::max<std::size_t>(opt_.target_vertices, 1);
    const std::size_t to_remove = n > target ? n - target : 0;
    ring_offsets_ = {0};
    // The node arrays at their final size (a growing vector would hold up to
    // twice that): one node per removal, rings of ~6.5 vertices on average.
    node_vertex_.reserve(to_remove);
    node_closed_.reserve(to_remove);
    node_offset_.reserve(to_remove);
    ring_offsets_.reserve(to_remove + 1);
    ring_vertices_.reserve(to_remove * 13 / 2);
    ring_weights_.reserve(to_remove * 13 / 2);
    created_corners_.reserve(to_remove * 9 / 2);

    cost_.assign(n, 0.0);
    valid_.assign(n, 0);
    stale_.assign(n, 0);
    mark_.assign(n, 0);
    least_rank_.assign(n, 0);
    plan_all(pool_, PlanWork::kCostOnly, [](Index) { return true; });

    std::size_t remaining = n, next_report = 0;
    std::uint32_t round = 0;
    while (remaining > target) {
      if (opt_.stop && opt_.stop->load(std::memory_order_relaxed)) throw PreprocessingStopped();
      // The candidates ran out above the target: a removal that a change two
      // rings away made valid (a diagonal no longer an edge, a neighbour's
      // valence) was never planned again. Plan every vertex left once more.
      // (With every check: the pool must not fill with removals that fail them.)
      if (window_.empty()) {
        tidy(pool_, pool_sorted_);
        if (pool_.empty() && (plan_all(pool_, PlanWork::kFull, [&](Index v) { return !removed_[v]; }), pool_.empty()))
          break;
        choose_window();
      }
      const std::size_t removed = remove_round(++round, remaining - target);
      // A window serves rounds until none removes anything from it.
      if (removed == 0) window_.clear();
      remaining -= removed;
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
    std::vector<double>().swap(cost_);
    std::vector<Index>().swap(pool_);
    std::vector<Plan>().swap(plans_);
    finish();
    if (opt_.progress) opt_.progress(1.0);
  }

 private:
  // Plans every vertex `which` accepts (in parallel) and appends the valid
  // ones to `pool`, with their costs.
  template <class Which>
  void plan_all(std::vector<Index>& pool, PlanWork work, Which which) {
    const std::size_t n = mesh_.positions().size();
    const std::size_t parts = static_cast<std::size_t>(std::max(opt_.threads, 1));
    std::vector<Plan> scratch(parts);
    parallel_ranges(parts, parts, [&](std::size_t part, std::size_t) {
      for (Index v = static_cast<Index>(n * part / parts); v < n * (part + 1) / parts; ++v) {
        if ((v & 1023) == 0 && opt_.stop && opt_.stop->load(std::memory_order_relaxed)) throw PreprocessingStopped();
        if (!which(v)) continue;
        valid_[v] = plan(v, scratch[part], nullptr, work) ? 1 : 0;
        stale_[v] = 0;
        if (valid_[v]) cost_[v] = scratch[part].cost;
      }
    });
    for (Index v = 0; v < n; ++v)
      if (valid_[v] && which(v)) pool.push_back(v);
  }

  // Ties go to the lower input id: the result does not depend on order_.
  bool cheaper(Index a, Index b) const { return cost_[a] != cost_[b] ? cost_[a] < cost_[b] : order_[a] < order_[b]; }

  // Drops removed and invalid vertices, and repeats, from a candidate list
  // whose first `sorted` entries are in vertex order, and sorts it (sorted
  // then covers it all).
  void tidy(std::vector<Index>& list, std::size_t& sorted) {
    const auto tail = list.begin() + static_cast<std::ptrdiff_t>(std::min(sorted, list.size()));
    std::sort(tail, list.end());
    std::inplace_merge(list.begin(), tail, list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    std::erase_if(list, [&](Index v) { return removed_[v] || !valid_[v]; });
    sorted = list.size();
  }

  // The window: about the cheapest share of the candidates by their last
  // known cost, cut at a pivot taken from a sample of them (one pass over
  // the pool instead of a selection); bound_ is the cost of the cheapest
  // candidate left out. It keeps the pool's vertex order, for the caches.
  // Precondition: the pool is tidy and not empty.
  void choose_window() {
    const auto by_cost = [&](Index a, Index b) { return cheaper(a, b); };
    const std::size_t wanted = std::clamp(pool_.size() / kWindowShare, kMinWindow, kMaxWindow);
    bound_ = std::numeric_limits<double>::infinity();
    window_.clear();
    if (wanted >= pool_.size()) {
      window_ = pool_;
    } else {
      std::vector<Index> sample;
      const std::size_t step = std::max<std::size_t>(pool_.size() / kPivotSample, 1);
      for (std::size_t i = 0; i < pool_.size(); i += step) sample.push_back(pool_[i]);
      const std::size_t q = sample.size() * wanted / pool_.size();
      std::nth_element(sample.begin(), sample.begin() + static_cast<std::ptrdiff_t>(q), sample.end(), by_cost);
      const Index pivot = sample[q];
      for (Index v : pool_)
        if (cheaper(v, pivot)) window_.push_back(v);
      bound_ = cost_[pivot];
      if (window_.size() > kMaxWindow) {
        std::nth_element(window_.begin(), window_.begin() + static_cast<std::ptrdiff_t>(kMaxWindow), window_.end(), by_cost);
        bound_ = cost_[window_[kMaxWindow]];
        window_.resize(kMaxWindow);
        std::sort(window_.begin(), window_.end());
      }
      if (window_.empty()) window_.push_back(pivot), bound_ = std::numeric_limits<double>::infinity();
    }
    window_sorted_ = window_.size();
  }

  // One round over the window; returns how many vertices it removed (at
  // most `budget`). Every candidate outside the window costs at least
  // bound_ (a removal makes its neighbours stale at their old cost, and one
  // it makes valid again joins the window at the removal's cost).
  std::size_t remove_round(std::uint32_t round, std::size_t budget) {
    const auto cheaper = [&](Index a, Index b) { return this->cheaper(a, b); };
    const double bound = bound_;
    const std::size_t window = window_.size();
    if (plans_.size() < window) plans_.resize(window);
    // Plan the candidates whose rings changed since their last plan; the
    // others' costs are still exact.
    std::vector<std::uint32_t> stale;
    for (std::size_t i = 0; i < window; ++i)
      if (stale_[window_[i]]) stale.push_back(static_cast<std::uint32_t>(i));
    // (In vertex order, as the window is: neighbours in the mesh are mostly
    // near in memory.)
    std::vector<std::uint8_t> planned(window, 0);
    parallel_steps(stale.size(), opt_.threads, opt_.stop, [&](std::size_t j) {
      const std::uint32_t i = stale[j];
      planned[i] = plan(window_[i], plans_[i], nullptr, PlanWork::kCostOnly) ? 1 : 2;
    });
    std::vector<std::uint32_t> order;
    order.reserve(window);
    for (std::size_t i = 0; i < window; ++i) {
      const Index v = window_[i];
      if (planned[i] == 2) valid_[v] = 0;
      if (planned[i] == 1) cost_[v] = plans_[i].cost;
      if (planned[i] != 0) stale_[v] = 0;
      if (valid_[v]) order.push_back(static_cast<std::uint32_t>(i));
    }
    // The candidates no dearer than any left out of the window, cheapest first.
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return cheaper(window_[a], window_[b]); });
    order.erase(std::find_if(order.begin(), order.end(), [&](std::uint32_t i) { return cost_[window_[i]] > bound; }),
                order.end());
    // Each one's neighbours gathered on all threads (the faces are scattered
    // in memory), so that the choice, which is sequential, reads only marks.
    // A candidate has at most kMaxRing faces (a stale one with more is
    // refused when planned): at most 2·kMaxRing corners besides itself.
    constexpr std::size_t kSlots = 2 * kMaxRing;
    neighbours_.resize(order.size() * kSlots);
    std::vector<std::uint8_t> neighbour_count(order.size());
    parallel_steps(order.size(), opt_.threads, nullptr, [&](std::size_t o) {
      const Index v = window_[order[o]];
      std::size_t c = 0;
      for (FaceId f : mesh_.vertex_faces(v))
        for (Index u : mesh_.face(f))
          if (u != v && c < kSlots) neighbours_[o * kSlots + c++] = u;
      neighbour_count[o] = static_cast<std::uint8_t>(c);
    });
    // A removal goes this round only if it is the cheapest of the candidates
    // whose closed rings meet its own (those within two edges): as the
    // thesis' one-at-a-time queue would take it before any of them, and
    // nothing it changes reaches a removal taken beside it. (Taking the
    // cheapest whose rings met no removal already chosen let a candidate go
    // before a cheaper neighbour two edges away: the coarse elephant's bend
    // was 9x further from the truth.) Each vertex keeps the cheapest rank
    // whose closed ring holds it; ranks go up, so the first is the least.
    const auto neighbours = [&](std::size_t o) {
      return std::span<const Index>(neighbours_.data() + o * kSlots, neighbour_count[o]);
    };
    for (std::size_t o = 0; o < order.size(); ++o) {
      const Index v = window_[order[o]];
      for (Index u : neighbours(o))
        if (mark_[u] != round) mark_[u] = round, least_rank_[u] = static_cast<std::uint32_t>(o);
      if (mark_[v] != round) mark_[v] = round, least_rank_[v] = static_cast<std::uint32_t>(o);
    }
    std::vector<std::uint32_t> picks;
    for (std::size_t o = 0; o < order.size() && picks.size() < budget; ++o) {
      const Index v = window_[order[o]];
      const auto least = [&](Index u) { return least_rank_[u] == o; };
      if (least(v) && std::all_of(neighbours(o).begin(), neighbours(o).end(), least)) picks.push_back(order[o]);
    }
    // A pick planned this round still needs its topology checked; one
    // planned in an earlier round has its cost, not its plan: plan it again
    // (a removal two rings away may have made it invalid since).
    parallel_steps(picks.size(), opt_.threads, opt_.stop, [&](std::size_t j) {
      const std::uint32_t i = picks[j];
      if (planned[i] == 1) {
        planned[i] = topology_ok(plans_[i]) ? 1 : 2;
      } else {
        plans_[i].cost = cost_[window_[i]];
        planned[i] = plan(window_[i], plans_[i], nullptr, PlanWork::kNoCost) ? 1 : 2;
      }
    });
    std::erase_if(picks, [&](std::uint32_t i) {
      if (planned[i] == 1) return false;
      valid_[window_[i]] = 0;
      return true;
    });
    perform_all(picks);

    // The picks' neighbours have new rings: their costs are stale, and one
    // that could not go before may now. Then drop what left the candidates.
    for (std::uint32_t i : picks) {
      const double c = plans_[i].cost;
      for (Index j : plans_[i].ring.ring) {
        stale_[j] = 1;
        if (valid_[j]) continue;
        valid_[j] = 1;
        cost_[j] = c;
        pool_.push_back(j);
        window_.push_back(j);
      }
    }
    tidy(window_, window_sorted_);
    return picks.size();
  }

  // A per-vertex array of the input in the local order.
  template <class T>
  std::vector<T> permuted(const std::vector<T>& by_input_id) const {
    std::vector<T> out(order_.size());
    for (std::size_t i = 0; i < order_.size(); ++i) out[i] = by_input_id[order_[i]];
    return out;
  }

  // Performs the chosen removals: ids and storage in pick order here, the
  // work itself on all threads (their closed rings are disjoint).
  void perform_all(const std::vector<std::uint32_t>& picks) {
    struct Slot {
      NodeId node;
      std::size_t ring_offset, corner_offset;
      FaceId first_face;
      std::size_t points_at = 0;
    };
    std::vector<Slot> slots(picks.size());
    std::size_t ring_total = ring_vertices_.size(), corner_total = created_corners_.size(), new_faces = 0;
    const FaceId first = static_cast<FaceId>(mesh_.face_count_ever());
    for (std::size_t j = 0; j < picks.size(); ++j) {
      const std::size_t k = plans_[picks[j]].ring.ring.size();
      slots[j] = {static_cast<NodeId>(node_vertex_.size() + j), ring_total, corner_total,
                  static_cast<FaceId>(first + new_faces), 0};
      ring_total += k;
      corner_total += k - 2;
      new_faces += k - 2;
      ring_offsets_.push_back(static_cast<Index>(ring_total));
    }
    mesh_.reserve_faces(new_faces);
    face_points_at_.resize(mesh_.face_count_ever(), 0);
    face_point_count_.resize(mesh_.face_count_ever(), 0);
    if (point_arena_.size() > 2 * node_vertex_.size() + (std::size_t{1} << 16)) compact_points();
    // Each removal's points (v and its fan's) get one slice of the arena.
    for (std::size_t j = 0; j < picks.size(); ++j) {
      slots[j].points_at = point_arena_.size();
      std::size_t points = 1;
      for (FaceId f : plans_[picks[j]].ring.fan) points += face_point_count_[f];
      point_arena_.resize(point_arena_.size() + points);
    }
    node_vertex_.resize(node_vertex_.size() + picks.size());
    node_closed_.resize(node_vertex_.size());
    node_offset_.resize(node_vertex_.size());
    ring_vertices_.resize(ring_total);
    ring_weights_.resize(ring_total);
    created_corners_.resize(corner_total);
    parallel_steps(picks.size(), opt_.threads, nullptr, [&](std::size_t j) {
      const Slot& s = slots[j];
      perform(window_[picks[j]], plans_[picks[j]], s.node, s.ring_offset, s.corner_offset, s.first_face, s.points_at);
    });
  }

  // Moves the live faces' points to a new arena, dropping dead faces' slices.
  void compact_points() {
    std::vector<Index> arena;
    arena.reserve(2 * node_vertex_.size() + (std::size_t{1} << 16));
    for (FaceId f = 0; f < face_point_count_.size(); ++f) {
      const std::uint32_t count = face_point_count_[f];
      if (count == 0) continue;
      const auto from = point_arena_.begin() + face_points_at_[f];
      face_points_at_[f] = static_cast<std::uint32_t>(arena.size());
      arena.insert(arena.end(), from, from + count);
    }
    point_arena_ = std::move(arena);
  }

  // Manifoldness of the planned removal: every diagonal must be a new edge,
  // and every ring vertex must keep valence ≥ 3 (≥ 2 on the boundary); the
  // latter also rejects collapsing a tetrahedron into a doubled triangle.
  bool topology_ok(const Plan& p) const {
    const std::vector<Index>& r = p.ring.ring;
    const std::size_t k = r.size();
    const bool closed = p.ring.closed;
    std::array<int, kMaxRing> gained{};
    if (!closed) ++gained[0], ++gained[k - 1];
    for (const auto& t : p.tris) {
      for (int c = 0; c < 3; ++c) {
        const int a = t[c], b = t[(c + 1) % 3];
        if (a > b) continue;  // each diagonal appears in two triangles; count it once
        const bool ring_edge = b == a + 1 || (closed && a == 0 && b == static_cast<int>(k) - 1);
        if (ring_edge || (!closed && a == 0 && b == static_cast<int>(k) - 1)) continue;
        if (mesh_.has_edge(r[a], r[b])) return false;
        ++gained[a], ++gained[b];
      }
    }
    for (std::size_t i = 0; i < k; ++i) {
      const std::size_t valence = mesh_.valence(r[i]) - 1 + gained[i];
      if (valence < (mesh_.is_boundary(r[i]) ? 2u : 3u)) return false;
    }
    return true;
  }

  // Plans the removal of v; false if it would break manifoldness, topology,
  // the boundary, flip or produce poor triangles.
  // `why`, when given, says which check refused (set only on refusal).
  // `work` may skip the topology checks or the cost (PlanWork).
  bool plan(Index v, Plan& p, BaseRefusal* why = nullptr, PlanWork work = PlanWork::kFull) const {
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
    if (!conformal_ring_map(x[v], r, x, closed, p.uv)) return refuse(BaseRefusal::kShape);
    if (!triangulate_polygon(p.uv, p.tris)) return refuse(BaseRefusal::kShape);

    if (work != PlanWork::kCostOnly && !topology_ok(p)) return refuse(BaseRefusal::kTopology);

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

    if (work == PlanWork::kNoCost) return true;
    // Error: how far v and the points parameterised in its fan would end up
    // from their true positions on the coarser mesh.
    double error = (image(p, locate(Vec2::Zero(), p.uv, p.tris)) - x[v]).norm();
    for (std::size_t i = 0; i < p.ring.fan.size(); ++i) {
      const FaceId f = p.ring.fan[i];
      // At most kCostSamplesPerFace, spread over the face's points.
      const std::size_t count = face_point_count_[f], stride = std::max<std::size_t>(count / kCostSamplesPerFace, 1);
      for (std::size_t s = 0; s < count; s += stride) {
        const Index q = point_arena_[face_points_at_[f] + s];
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
    const PointBary& b = point_bary_[q];
    const double bary[3] = {b[0], b[1], 1.0 - double(b[0]) - double(b[1])};
    for (int c = 0; c < 3; ++c) {
      if (t[c] == p.ring.ring[i])
        uv += bary[c] * p.uv[i];
      else if (t[c] == p.ring.ring[(i + 1) % k])
        uv += bary[c] * p.uv[(i + 1) % k];
    }
    return uv;
  }

  // Removes v as planned: node `node`, its ring at ring_offset, its created
  // faces' corners at corner_offset and ids from first_face, its points at
  // points_at in the arena (perform_all reserved them). Touches only v's
  // closed ring, its fan and new faces.
  void perform(Index v, const Plan& p, NodeId node, std::size_t ring_offset, std::size_t corner_offset,
               FaceId first_face, std::size_t points_at) {
    const auto x = mesh_.positions();
    const std::vector<Index>& r = p.ring.ring;

    // Ring coordinates for direct recovery (thesis eq. 3.10). The hierarchy
    // keeps the weights in 16-bit fixed point: round them first and compute
    // the offset in the frame of the rounded weights, so that the stored pair
    // puts v back where it was (only the offset's own float rounding remains).
    const std::vector<std::uint16_t> stored = quantize_ring_weights(ring_weights(x[v], r, x, p.ring.closed));
    std::copy(stored.begin(), stored.end(), ring_weights_.begin() + static_cast<std::ptrdiff_t>(ring_offset));
    for (std::size_t i = 0; i < r.size(); ++i) ring_vertices_[ring_offset + i] = order_[r[i]];
    node_vertex_[node] = order_[v];
    node_closed_[node] = p.ring.closed ? 1 : 0;
    node_offset_[node] = ring_frame(r, std::span<const std::uint16_t>(stored), x, p.ring.closed).to_local(x[v]).cast<float>();

    // Faces: the fan dies, the hole's triangulation is born. Which faces
    // died, and so the dependency edges, are derived (hierarchy/node_graph.h).
    for (std::size_t j = 0; j < p.tris.size(); ++j) {
      const auto& t = p.tris[j];
      mesh_.set_face(first_face + static_cast<FaceId>(j), {r[t[0]], r[t[1]], r[t[2]]});
      // Ring corners, as the hierarchy keeps created faces (a ring has ≤ kMaxRingSize vertices).
      created_corners_[corner_offset + j] = {static_cast<std::uint8_t>(t[0]), static_cast<std::uint8_t>(t[1]),
                                             static_cast<std::uint8_t>(t[2])};
    }

    // MAPS: v and every point in its fan move into the new triangles through
    // the same planar map (thesis §3.1.2): located first, then written to
    // this removal's arena slice grouped by their new face (v first, then
    // the fan's points in fan order).
    std::array<std::uint32_t, kMaxRing> count{};
    auto place = [&](Index q, const Vec2& uv) {
      const Location l = locate(uv, p.uv, p.tris);
      point_face_[q] = first_face + static_cast<FaceId>(l.tri);
      point_bary_[q] = {static_cast<float>(l.bary[0]), static_cast<float>(l.bary[1])};
      ++count[static_cast<std::size_t>(l.tri)];
    };
    const auto fan_points = [&](std::size_t i) {
      const FaceId f = p.ring.fan[i];
      return std::span<const Index>(point_arena_.data() + face_points_at_[f], face_point_count_[f]);
    };
    place(v, Vec2::Zero());
    for (std::size_t i = 0; i < p.ring.fan.size(); ++i)
      for (Index q : fan_points(i)) place(q, fan_uv(p, i, q));
    std::array<std::size_t, kMaxRing> at{};
    for (std::size_t j = 0, next = points_at; j < p.tris.size(); ++j) {
      const FaceId f = first_face + static_cast<FaceId>(j);
      face_points_at_[f] = static_cast<std::uint32_t>(next);
      face_point_count_[f] = count[j];
      at[j] = next;
      next += count[j];
    }
    // The fan's slices are read before anything is written: this slice is new.
    point_arena_[at[point_face_[v] - first_face]++] = v;
    for (std::size_t i = 0; i < p.ring.fan.size(); ++i)
      for (Index q : fan_points(i)) point_arena_[at[point_face_[q] - first_face]++] = q;
    for (FaceId f : p.ring.fan) face_point_count_[f] = 0;
    for (FaceId f : p.ring.fan) mesh_.kill_face(f);
    removed_[v] = 1;
  }

  // Base mesh and MAPS coordinates relative to it.
  void finish() {
    const std::size_t n = mesh_.positions().size();
    out_.original_faces = original_faces_;  // face ids: the input's, then the removals'
    out_.node_vertex = std::move(node_vertex_);
    out_.node_closed = std::move(node_closed_);
    out_.ring_offsets = std::move(ring_offsets_);
    out_.ring_vertices = std::move(ring_vertices_);
    out_.ring_weights = std::move(ring_weights_);
    out_.node_offset = std::move(node_offset_);
    out_.created_corners = std::move(created_corners_);
    std::vector<std::uint32_t>().swap(face_points_at_);
    std::vector<std::uint32_t>().swap(face_point_count_);
    std::vector<Index>().swap(point_arena_);
    out_.base_vertices.clear();
    for (Index v = 0; v < n; ++v)
      if (!removed_[v]) out_.base_vertices.push_back(order_[v]);
    std::sort(out_.base_vertices.begin(), out_.base_vertices.end());
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
        maps_face[order_[v]] = base_index[point_face_[v]];
        const PointBary& b = point_bary_[v];
        maps_bary[order_[v]] = quantize_barycentric(Vec3(b[0], b[1], 1.0 - double(b[0]) - double(b[1])));
      } else {
        // A base vertex is the corner of its first live face.
        const FaceId f = mesh_.vertex_faces(v).front();
        const Triangle& t = mesh_.face(f);
        maps_face[order_[v]] = base_index[f];
        maps_bary[order_[v]] = quantize_barycentric(Vec3(t[0] == v, t[1] == v, t[2] == v));
      }
    }
    out_.maps_face = std::move(maps_face);
    out_.maps_bary = std::move(maps_bary);
  }

  const SimplifyOptions& opt_;
  const std::vector<Triangle>& original_faces_;
  // The simplifier works on the mesh in a spatially local vertex order (it
  // is bound by memory latency: 1.2× faster on the 435k dragon) and speaks
  // input ids in everything it writes. order_[local] = input id.
  std::vector<Index> order_;
  TriMesh local_;
  DynamicMesh mesh_;
  std::vector<double> saliency_;
  Hierarchy& out_;
  double diag_ = 1.0;
  std::vector<double> curvature_;
  // Removed vertices parameterised in each face (MAPS). A face gets all its
  // points when it is born and loses them all when it dies, so each face's
  // points are one slice of one arena (a vector per face was 3.35M small
  // allocations at 435k vertices); dead faces' slices are dropped by
  // compact_points().
  std::vector<Index> point_arena_;
  std::vector<std::uint32_t> face_points_at_;
  std::vector<std::uint32_t> face_point_count_;
  std::vector<FaceId> point_face_;  // per removed vertex: its current face
  // ... and its first two barycentrics there: float is ~100× finer than the
  // file's 16 bits, at a third of the memory.
  using PointBary = std::array<float, 2>;
  std::vector<PointBary> point_bary_;
  std::vector<std::uint8_t> removed_;

  // Candidates: each vertex's last known cost and whether its last plan was
  // valid; the pool of candidates; the plans of the round's window; per
  // vertex the last round whose candidates' closed rings held it, and the
  // least rank among them.
  std::vector<double> cost_;
  std::vector<std::uint8_t> valid_;
  std::vector<std::uint8_t> stale_;  // its ring changed since its cost was computed
  std::vector<Index> pool_;
  std::vector<Index> window_;      // the candidates the rounds plan, until none goes
  double bound_ = 0.0;             // no candidate outside the window costs less
  std::size_t pool_sorted_ = 0, window_sorted_ = 0;  // prefixes in vertex order (tidy)
  std::vector<Index> neighbours_;  // the round's choice: each candidate's neighbours
  std::vector<Plan> plans_;
  std::vector<std::uint32_t> mark_;
  std::vector<std::uint32_t> least_rank_;  // valid where mark_ is the round

  // The hierarchy's node arrays as they grow (moved into out_ at the end).
  std::vector<Index> node_vertex_;
  std::vector<std::uint8_t> node_closed_;
  std::vector<Index> ring_offsets_;
  std::vector<Index> ring_vertices_;
  std::vector<std::uint16_t> ring_weights_;
  std::vector<Vec3f> node_offset_;
  std::vector<RingCorners> created_corners_;
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

void simplify(const TriMesh& mesh, VertexTraits traits, const SimplifyOptions& options, Hierarchy& out) {
  const std::size_t n = mesh.positions.size();
  if (traits.curvature.size() != n || traits.saliency.size() != n || traits.boundary.size() != n)
    throw std::invalid_argument("simplify: one curvature, saliency and boundary flag per vertex");
  Simplifier(mesh, traits, options, out).run();
}

}  // namespace filigree
