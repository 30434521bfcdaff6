#include "runtime/cut.h"

#include <algorithm>
#include <atomic>
#include <stdexcept>
#include <string>
#include <cmath>
#include <thread>

#include "geometry/cotangent_laplacian.h"

namespace filigree {
namespace {

// A swap must improve the acuteness handed to optimisation by this factor.
constexpr double kSwapGain = 1.5;
// Weight of the fraction of a node's mesh neighbours that are optimised.
constexpr double kGrowthBonus = 4.0;

// One triangle of a scored patch: its corners, rest and posed normals
// (length twice the area).
struct PatchFace {
  Index v[3];
  Vec3 rest_normal, posed_normal;
};

// Σ over the patch of area·((Γ−1)² + (γ−1)²), with Γ ≥ γ the singular values
// of the affine map taking the rest triangle to the posed one (thesis §3.3.1,
// eq. 3.7), and the patch's rest area. With G_p, G_x the Gram matrices of the
// rest and posed edge vectors, Γ² + γ² = tr(G_p⁻¹ G_x) and Γγ = |n_x| / |n_p|,
// so Γ + γ = √(Γ² + γ² + 2Γγ): no SVD, two square roots.
void add_stretch(const PatchFace& f, std::span<const Vec3> p, const std::vector<Vec3>& x, double& stretch_sum,
                 double& area_sum) {
  const double rest_area2 = f.rest_normal.squaredNorm();  // det G_p
  if (!(rest_area2 > 0.0)) return;                        // a degenerate rest triangle has no area to weigh
  const Vec3 e1 = p[f.v[1]] - p[f.v[0]], e2 = p[f.v[2]] - p[f.v[0]];
  const Vec3 g1 = x[f.v[1]] - x[f.v[0]], g2 = x[f.v[2]] - x[f.v[0]];
  const double a = e1.squaredNorm(), b = e1.dot(e2), c = e2.squaredNorm();
  const double trace = (c * g1.squaredNorm() - 2.0 * b * g1.dot(g2) + a * g2.squaredNorm()) / rest_area2;
  const double product = std::sqrt(f.posed_normal.squaredNorm() / rest_area2);
  const double sum = std::sqrt(std::max(trace + 2.0 * product, 0.0));
  const double area = 0.5 * std::sqrt(rest_area2);
  stretch_sum += area * std::max(trace - 2.0 * sum + 2.0, 0.0);
  area_sum += area;
}

// Angle between two face normals.
double angle(const Vec3& n1, const Vec3& n2) { return std::atan2(n1.cross(n2).norm(), n1.dot(n2)); }

// Largest patch scored without a heap allocation; the simplifier's rings
// hold at most 32 vertices.
constexpr std::size_t kPatchFaces = 64;

}  // namespace

AdaptiveCut::AdaptiveCut(const NodeGraph& graph, const CotangentLaplacian& laplacian, double threshold)
    : h_(graph.hierarchy()), graph_(graph), laplacian_(laplacian), cut_(graph), recoverable_(place_), removable_(place_) {
  reset(threshold);
}

void AdaptiveCut::release_queues() {
  // Swapped with empty vectors: assigning {} would keep the capacity.
  recoverable_.release();
  removable_.release();
  std::vector<float>().swap(score_);
  std::vector<Index>().swap(place_);
  std::vector<Index>().swap(uf_parent_);
  std::vector<double>().swap(uf_size_);
  std::vector<double>().swap(uf_constraints_);
  std::vector<Index>().swap(changed_);
  std::vector<bool>().swap(moved_);
  moved_id_ = MovedIds();
  next_block_ = 0;
  estimate_ = 0.0;
}

void AdaptiveCut::reset(double threshold) {
  threshold_ = threshold;
  scored_since_move_ = 0;
  release_queues();
  regions_ = Regions{};
  const std::size_t n = h_.vertex_count();
  if (threshold == kInfinity) {
    cut_ = CutState(graph_);
    in_cut_.assign(n, false);
    for (Index v : h_.base_vertices) in_cut_[v] = true;
    regions_ = find_regions(laplacian_, in_cut_);
    return;
  }
  cut_ = CutState::full(h_, &graph_);
  in_cut_.assign(n, true);
  if (!adaptive()) return;
  // The full cut: exactly the nodes without children may leave it, and none
  // may be recovered; all score 0, so the removable queue is in node order.
  score_.assign(h_.node_count(), 0.0f);
  place_.assign(h_.node_count(), kNone);
  for (NodeId k = 0; k < h_.node_count(); ++k)
    if (graph_.children_of(k).empty()) removable_.push(k, 0.0f);
  moved_.assign(n, false);
}

void AdaptiveCut::set_threshold(double threshold) {
  const auto special = [](double t) { return t <= 0.0 || t == kInfinity; };
  if (special(threshold) || special(threshold_)) {
    reset(threshold);
  } else {
    if (threshold != threshold_) scored_since_move_ = 0;  // another T: the cut has somewhere to go
    threshold_ = threshold;
  }
}

double AdaptiveCut::evaluate(NodeId k, Index v, const std::vector<Vec3>& x) const {
  // The patch: the faces k's recovery would delete, or its removal would.
  const bool recover = cut_.can_recover(k);
  if (!recover && !cut_.can_remove(k)) return -1.0;
  const std::size_t count = recover ? h_.ring_size(k) - 2 : h_.fan_size(k);
  const auto& p = h_.rest_positions;
  PatchFace local[kPatchFaces];
  std::vector<PatchFace> heap;
  PatchFace* patch = local;
  if (count > kPatchFaces) {
    heap.resize(count);
    patch = heap.data();
  }
  double stretch_sum = 0.0, area_sum = 0.0, bend = 0.0, edge_sum = 0.0;
  for (std::size_t i = 0; i < count; ++i) {
    const Triangle t = recover ? h_.created_face(k, i) : h_.fan_face(k, i);
    PatchFace& f = patch[i];
    f.v[0] = t[0], f.v[1] = t[1], f.v[2] = t[2];
    f.rest_normal = (p[t[1]] - p[t[0]]).cross(p[t[2]] - p[t[0]]);
    f.posed_normal = (x[t[1]] - x[t[0]]).cross(x[t[2]] - x[t[0]]);
    add_stretch(f, p, x, stretch_sum, area_sum);
  }
  // Normal difference (thesis §3.3.2, eq. 3.8) on edges shared inside the
  // patch: the change of the dihedral angle, weighed by the rest edge length.
  for (std::size_t i = 0; i < count; ++i) {
    const PatchFace& t = patch[i];
    for (std::size_t j = i + 1; j < count; ++j) {
      const PatchFace& s = patch[j];
      for (int c = 0; c < 3; ++c) {
        const Index a = t.v[c], b = t.v[(c + 1) % 3];
        for (int e = 0; e < 3; ++e) {
          if (s.v[e] != b || s.v[(e + 1) % 3] != a) continue;
          const double len = (p[a] - p[b]).norm();
          bend += len * std::abs(angle(t.posed_normal, s.posed_normal) - angle(t.rest_normal, s.rest_normal));
          edge_sum += len;
        }
      }
    }
  }
  const double acuteness = (area_sum > 0.0 ? stretch_sum / area_sum : 0.0) + (edge_sum > 0.0 ? bend / edge_sum : 0.0);
  // Favour nodes next to optimised vertices, in both queues: un-recovering
  // them grows regions instead of scattering one-vertex regions that the cut
  // pins in place (percolation, DESIGN §2.2.4); recovering isolated ones
  // first removes exactly those useless islands.
  double free_neighbours = 0.0;
  const double degree = static_cast<double>(laplacian_.offsets[v + 1] - laplacian_.offsets[v]);
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) free_neighbours += in_cut_[laplacian_.neighbors[i]] ? 0.0 : 1.0;
  return acuteness * (1.0 + kGrowthBonus * free_neighbours / std::max(degree, 1.0));
}

std::size_t AdaptiveCut::block_at(std::size_t ordinal) const {
  // Blocks b ≡ p (mod kPhases) come at positions [start_p, start_p + count_p).
  const std::size_t block_count = (h_.vertex_count() + kScoreBlock - 1) / kScoreBlock;
  for (std::size_t p = 0, start = 0; p < kPhases; ++p) {
    const std::size_t count = p < block_count ? (block_count - p + kPhases - 1) / kPhases : 0;
    if (ordinal < start + count) return (p + kPhases * (ordinal - start)) * kScoreBlock;
    start += count;
  }
  return 0;  // not reached: ordinal < block_count
}

void AdaptiveCut::score_block(std::size_t first, std::size_t count, const std::vector<Vec3>& x, float* out) const {
  // Scoring waits on memory: a node's cut state, its faces, their corners and
  // its ring lie scattered. Each pass below issues the independent loads the
  // next one needs, so that many are in flight at once and the scoring pass
  // finds its data in cache.
  NodeId node[kScoreBlock];
  Index vertex[kScoreBlock];
  for (std::size_t i = 0; i < count; ++i) {
    vertex[i] = static_cast<Index>(first + i);
    node[i] = graph_.node_of_vertex(vertex[i]);
    if (node[i] != kNone) cut_.prefetch(node[i]);
  }
  std::uint16_t frontier[kScoreBlock];
  bool recovers[kScoreBlock];  // per frontier entry: its patch is the recovery's (else the removal's)
  std::size_t m = 0;
  for (std::size_t i = 0; i < count; ++i) {
    out[i] = -1.0f;
    const NodeId k = node[i];
    if (k == kNone) continue;
    const bool recover = cut_.can_recover(k);
    if (!recover && !cut_.can_remove(k)) continue;
    __builtin_prefetch(&h_.ring_offsets[k]);
    __builtin_prefetch(&laplacian_.offsets[vertex[i]]);
    recovers[m] = recover;
    frontier[m++] = static_cast<std::uint16_t>(i);
  }
  // A patch's corners are k's vertex and its ring: a removal's faces are
  // its fan, a recovery's its ring corners.
  for (std::size_t j = 0; j < m; ++j) {
    const NodeId k = node[frontier[j]];
    __builtin_prefetch(h_.ring(k).data());
    if (recovers[j]) __builtin_prefetch(&h_.created_corners[h_.first_created_face(k) - h_.original_face_count()]);
    __builtin_prefetch(&laplacian_.neighbors[laplacian_.offsets[vertex[frontier[j]]]]);
  }
  for (std::size_t j = 0; j < m; ++j) {
    const NodeId k = node[frontier[j]];
    __builtin_prefetch(&h_.rest_positions[vertex[frontier[j]]]);
    __builtin_prefetch(&x[vertex[frontier[j]]]);
    for (Index c : h_.ring(k)) {
      __builtin_prefetch(&h_.rest_positions[c]);
      __builtin_prefetch(&x[c]);
    }
  }
  for (std::size_t j = 0; j < m; ++j) {
    const std::size_t i = frontier[j];
    out[i] = static_cast<float>(evaluate(node[i], vertex[i], x));
  }
}

void AdaptiveCut::place(NodeId k) {
  auto move_to = [&](auto& into, auto& other) {
    if (other.contains(k)) other.erase(k);
    if (into.contains(k)) {
      into.update(k, score_[k]);
    } else {
      into.push(k, score_[k]);
    }
  };
  if (cut_.can_recover(k)) {
    move_to(recoverable_, removable_);
  } else if (cut_.can_remove(k)) {
    move_to(removable_, recoverable_);
  } else if (recoverable_.contains(k)) {
    recoverable_.erase(k);
  } else if (removable_.contains(k)) {
    removable_.erase(k);
  }
}

void AdaptiveCut::place_around(NodeId k) {
  place(k);
  for (NodeId p : graph_.parents_of(k)) place(p);
  for (NodeId c : graph_.children_of(k)) place(c);
}

void AdaptiveCut::note_change(Index v) {
  if (moved_[v]) return;
  moved_[v] = true;
  changed_.push_back(v);
}

void AdaptiveCut::MovedIds::set(Index v, Index id) {
  if (2 * (used_ + 1) > slots_.size()) {
    std::vector<std::pair<Index, Index>> old(std::max<std::size_t>(64, 2 * slots_.size()), {kNone, kNone});
    old.swap(slots_);
    used_ = 0;
    for (const auto& [u, i] : old)
      if (u != kNone) set(u, i);
  }
  const std::size_t s = find(v);
  if (slots_[s].first == kNone) ++used_;
  slots_[s] = {v, id};
}

Index AdaptiveCut::MovedIds::get(Index v) const {
  if (slots_.empty()) return kNone;
  const std::size_t s = find(v);
  return slots_[s].first == v ? slots_[s].second : kNone;
}

std::size_t AdaptiveCut::MovedIds::find(Index v) const {
  const std::size_t mask = slots_.size() - 1;
  std::size_t s = (static_cast<std::size_t>(v) * 0x9E3779B97F4A7C15ull >> 20) & mask;
  while (slots_[s].first != kNone && slots_[s].first != v) s = (s + 1) & mask;
  return s;
}

void AdaptiveCut::MovedIds::clear() {
  if (used_ > 0) std::fill(slots_.begin(), slots_.end(), std::pair<Index, Index>{kNone, kNone});
  used_ = 0;
}

Index AdaptiveCut::region_root(Index v) {
  Index r = moved_[v] ? moved_id_.get(v) : regions_.region_of[v];
  while (uf_parent_[r] != r) r = uf_parent_[r] = uf_parent_[uf_parent_[r]];
  return r;
}

double AdaptiveCut::delta_unrecover(NodeId k) {
  const Index v = h_.node_vertex[k];
  double n = 1.0, c = 0.0, before = 0.0;
  Index roots[64];
  int count = 0;
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) {
    const Index j = laplacian_.neighbors[i];
    if (in_cut_[j]) {
      c += 1.0;
      continue;
    }
    const Index r = region_root(j);
    if (std::find(roots, roots + count, r) != roots + count || count == 64) continue;
    roots[count++] = r;
    n += uf_size_[r];
    c += uf_constraints_[r] - 1.0;  // v stops being one of its constraints
    before += uf_size_[r] * uf_size_[r] + uf_constraints_[r] * uf_constraints_[r];
  }
  return n * n + c * c - before;
}

void AdaptiveCut::recover(NodeId k) {
  const Index v = h_.node_vertex[k];
  const Index r = region_root(v);
  const double n = uf_size_[r], c = uf_constraints_[r];
  const double n2 = n - 1.0, c2 = n2 > 0.0 ? c + 1.0 : 0.0;  // a region of one vanishes
  estimate_ += n2 * n2 + c2 * c2 - n * n - c * c;
  uf_size_[r] = n2;
  uf_constraints_[r] = c2;
  note_change(v);
  moved_id_.set(v, kNone);
  cut_.recover(k);
  in_cut_[v] = true;
  place_around(k);
}

void AdaptiveCut::unrecover(NodeId k) {
  const Index v = h_.node_vertex[k];
  estimate_ += delta_unrecover(k);
  const Index fresh = static_cast<Index>(uf_parent_.size());
  uf_parent_.push_back(fresh);
  uf_size_.push_back(1.0);
  uf_constraints_.push_back(0.0);
  for (Index i = laplacian_.offsets[v]; i < laplacian_.offsets[v + 1]; ++i) {
    const Index j = laplacian_.neighbors[i];
    if (in_cut_[j]) {
      uf_constraints_[fresh] += 1.0;
      continue;
    }
    const Index r = region_root(j);
    if (r == fresh) continue;
    uf_parent_[r] = fresh;
    uf_size_[fresh] += uf_size_[r];
    uf_constraints_[fresh] += uf_constraints_[r] - 1.0;
  }
  note_change(v);
  moved_id_.set(v, fresh);
  cut_.remove(k);
  in_cut_[v] = false;
  place_around(k);
}

void AdaptiveCut::rebuild_regions() {
  // Vertices that moved and came back (undone moves) change no region.
  const bool any_region = !regions_.region_of.empty();
  std::erase_if(changed_, [&](Index v) {
    moved_[v] = false;
    return in_cut_[v] != (any_region && regions_.region_of[v] != kNone);
  });
  update_regions(laplacian_, in_cut_, changed_, regions_);
  changed_.clear();
  moved_id_.clear();
  sync_estimate();
}

void AdaptiveCut::sync_estimate() {
  estimate_ = regions_.performance_estimate();
  const std::size_t count = regions_.count();
  uf_parent_.resize(count);
  uf_size_.resize(count);
  uf_constraints_.resize(count);
  for (Index r = 0; r < count; ++r) {
    uf_parent_[r] = r;
    uf_size_[r] = static_cast<double>(regions_.size(r));
    uf_constraints_[r] = static_cast<double>(regions_.constraints[r]);
  }
}

std::size_t AdaptiveCut::update(const std::vector<Vec3>& positions, std::size_t eval_budget, std::size_t move_budget,
                                int threads) {
  const std::size_t nodes = h_.node_count();
  if (nodes == 0 || !adaptive()) return 0;
  // Rescoring reads the cut and writes only its own slots, so blocks are
  // scored in parallel; the queues are then updated in the visiting order.
  const std::size_t n = h_.vertex_count();
  const std::size_t block_count = (n + kScoreBlock - 1) / kScoreBlock;
  const std::size_t blocks = std::min(block_count, (eval_budget + kScoreBlock - 1) / kScoreBlock);
  std::vector<float> scores(blocks * kScoreBlock);
  std::vector<std::size_t> firsts(blocks);
  for (std::size_t b = 0; b < blocks; ++b) firsts[b] = block_at((next_block_ + b) % block_count);
  next_block_ = (next_block_ + blocks) % block_count;
  auto block_size = [&](std::size_t b) { return std::min(kScoreBlock, n - firsts[b]); };
  {
    constexpr std::size_t kChunk = 8;  // blocks per hand-out
    std::atomic<std::size_t> next{0};
    auto work = [&] {
      for (std::size_t begin = next.fetch_add(kChunk); begin < blocks; begin = next.fetch_add(kChunk))
        for (std::size_t b = begin; b < std::min(begin + kChunk, blocks); ++b)
          score_block(firsts[b], block_size(b), positions, scores.data() + b * kScoreBlock);
    };
    const int t = std::max(1, std::min<int>(threads, static_cast<int>((blocks + kChunk - 1) / kChunk)));
    std::vector<std::jthread> pool;
    for (int i = 1; i < t; ++i) pool.emplace_back(work);
    work();
  }
  for (std::size_t b = 0; b < blocks; ++b) {
    const float* block_scores = scores.data() + b * kScoreBlock;
    const std::size_t size = block_size(b);
    for (std::size_t i = 0; i < size; ++i) {
      if (i + 8 < size && block_scores[i + 8] >= 0.0f) {  // the queue slot lies scattered
        const NodeId ahead = graph_.node_of_vertex(firsts[b] + i + 8);
        __builtin_prefetch(&place_[ahead]);
        __builtin_prefetch(&score_[ahead]);
      }
      if (block_scores[i] < 0.0f) continue;
      const NodeId k = graph_.node_of_vertex(firsts[b] + i);
      score_[k] = block_scores[i];
      place(k);
    }
  }

  auto top = [](const auto& queue) { return queue.empty() ? kNone : queue.top().node; };
  std::size_t moves = 0;
  // Over budget: recover the mildest nodes until the estimate fits.
  while (estimate_ > threshold_) {
    const NodeId a = top(recoverable_);
    if (a == kNone) break;
    recover(a);
    ++moves;
  }
  // Under budget: give the most acute node to optimisation, alone if it fits,
  // else paired with recovering the mildest (thesis §3.3 pair moves).
  while (moves < move_budget) {
    const NodeId b = top(removable_);
    if (b == kNone) break;
    const double grow = delta_unrecover(b);
    if (estimate_ + grow <= threshold_) {
      unrecover(b);
      ++moves;
      continue;
    }
    // Swap only for a clear gain, so that scores that shift a little from
    // frame to frame do not make the cut oscillate.
    const NodeId a = top(recoverable_);
    if (a == kNone || !(score_[b] > kSwapGain * score_[a] + 1e-9)) break;
    // An undone move is no move: it leaves the cut, the regions and their
    // factorisations as they were.
    const double before = estimate_;
    unrecover(b);
    if (!cut_.can_recover(a)) {  // b was a's parent: undo and stop
      recover(b);
      break;
    }
    recover(a);
    if (estimate_ > threshold_) {  // the pair does not fit after all: undo it
      unrecover(a);
      recover(b);
      estimate_ = std::max(estimate_, before);
      break;
    }
    moves += 2;
  }
  if (!changed_.empty()) rebuild_regions();
  if (moves > 0) {
    scored_since_move_ = 0;
  } else {
    for (std::size_t b = 0; b < blocks; ++b) scored_since_move_ += block_size(b);
  }
  return moves;
}

CutSnapshot AdaptiveCut::snapshot() const {
  CutSnapshot out;
  if (!adaptive()) return out;
  for (NodeId k = 0; k < h_.node_count(); ++k)
    if (!cut_.recovered(k)) out.unrecovered.push_back(k);
  out.scores = score_;
  out.next_block = next_block_;
  return out;
}

void AdaptiveCut::restore(const CutSnapshot& snapshot) {
  if (!adaptive() || snapshot.empty()) return;
  const std::size_t block_count = (h_.vertex_count() + kScoreBlock - 1) / kScoreBlock;
  if (snapshot.scores.size() != h_.node_count() || snapshot.next_block >= std::max<std::size_t>(block_count, 1))
    throw std::invalid_argument("the cut snapshot is of another mesh (" + std::to_string(snapshot.scores.size()) +
                                " nodes for " + std::to_string(h_.node_count()) + ")");
  reset(threshold_);
  try {
    // Ascending node ids remove children before their parents (the reverse
    // of recovery_order).
    NodeId previous = kNone;
    for (const NodeId k : snapshot.unrecovered) {
      if (k >= h_.node_count() || (previous != kNone && k <= previous) || !cut_.can_remove(k))
        throw std::invalid_argument("the cut snapshot's node " + std::to_string(k) + " cannot leave the cut");
      cut_.remove(k);
      in_cut_[h_.node_vertex[k]] = false;
      previous = k;
    }
  } catch (const std::exception&) {
    reset(threshold_);
    throw;
  }
  score_ = snapshot.scores;
  next_block_ = snapshot.next_block;
  regions_ = find_regions(laplacian_, in_cut_);
  sync_estimate();
  // Queue membership and order follow from the cut and the scores alone
  // (ties go to the lower node id), so this is the queues update() left.
  for (NodeId k = 0; k < h_.node_count(); ++k) place(k);
}

std::size_t AdaptiveCut::memory_bytes() const {
  return cut_.memory_bytes() + in_cut_.capacity() / 8 + regions_.memory_bytes() + score_.capacity() * sizeof(float) +
         place_.capacity() * sizeof(Index) + recoverable_.memory_bytes() + removable_.memory_bytes() +
         uf_parent_.capacity() * sizeof(Index) + (uf_size_.capacity() + uf_constraints_.capacity()) * sizeof(double) +
         changed_.capacity() * sizeof(Index) + moved_.capacity() / 8 + moved_id_.memory_bytes();
}

}  // namespace filigree
