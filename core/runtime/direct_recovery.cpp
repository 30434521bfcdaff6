#include "runtime/direct_recovery.h"

#include <algorithm>
#include <barrier>
#include <thread>

#include "geometry/ring_frame.h"
#include "hierarchy/cut_state.h"

namespace filigree {
namespace {
constexpr std::size_t kPrefetchDistance = 8;
constexpr std::size_t kNodesPerThread = 100000;
}  // namespace

DirectRecovery::DirectRecovery(const Hierarchy& h) {
  std::vector<std::size_t> level(h.node_count(), 0);
  std::size_t depth = 0;
  for (std::size_t k = h.node_count(); k-- > 0;) {
    for (NodeId p : h.parents_of(static_cast<NodeId>(k))) level[k] = std::max(level[k], level[p] + 1);
    depth = std::max(depth, level[k] + 1);
  }
  std::vector<std::vector<NodeId>> buckets(depth);
  for (std::size_t k = 0; k < h.node_count(); ++k) buckets[level[k]].push_back(static_cast<NodeId>(k));
  // Within a level, nodes go in Morton order of their rest position, so that
  // consecutive nodes share ring vertices and their loads hit the cache.
  Vec3 lo = h.rest_positions[0], hi = lo;
  for (const Vec3& p : h.rest_positions) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
  const Vec3 scale = (hi - lo).cwiseMax(1e-300).cwiseInverse() * 1023.0;
  auto morton = [&](NodeId k) {
    const Vec3 q = (h.rest_positions[h.node_vertex[k]] - lo).cwiseProduct(scale);
    std::uint64_t code = 0;
    for (int bit = 9; bit >= 0; --bit)
      for (int axis = 0; axis < 3; ++axis) code = code << 1 | ((static_cast<std::uint64_t>(q[axis]) >> bit) & 1u);
    return code;
  };
  for (auto& bucket : buckets) {
    std::vector<std::pair<std::uint64_t, NodeId>> keyed;
    for (NodeId k : bucket) keyed.emplace_back(morton(k), k);
    std::sort(keyed.begin(), keyed.end());
    for (std::size_t i = 0; i < keyed.size(); ++i) bucket[i] = keyed[i].second;
    for (NodeId k : bucket) {
      node_.push_back(k);
      vertex_.push_back(h.node_vertex[k]);
      closed_.push_back(h.node_closed[k]);
      offset_.push_back(h.node_offset[k]);
      weights_.insert(weights_.end(), h.weights(k).begin(), h.weights(k).end());
    }
    level_offsets_.push_back(static_cast<Index>(node_.size()));
  }
  // Private order: base vertices first, then node i's vertex at base + i.
  base_vertices_ = h.base_vertices;
  std::vector<Index> private_index(h.vertex_count(), kNone);
  for (Index i = 0; i < base_vertices_.size(); ++i) private_index[base_vertices_[i]] = i;
  for (Index i = 0; i < node_.size(); ++i) private_index[vertex_[i]] = static_cast<Index>(base_vertices_.size() + i);
  for (NodeId k : node_) {
    for (Index v : h.ring(k)) ring_.push_back(private_index[v]);
    ring_offsets_.push_back(static_cast<Index>(ring_.size()));
  }
  work_.resize(h.vertex_count());
}

void DirectRecovery::recover(const CutState& cut, std::vector<Vec3>& x, int threads) const {
  if (cut.recovered_count() == 0) return;  // whole-mesh optimisation: nothing to place
  // A barrier per level costs tens of microseconds on a busy machine: below
  // ~100k nodes per thread one thread is faster.
  const int t = std::clamp(static_cast<int>(node_.size() / kNodesPerThread), 1, std::max(1, threads));
  const std::size_t m = base_vertices_.size();
  for (std::size_t i = 0; i < m; ++i) work_[i] = x[base_vertices_[i]];
  // One team for all levels, a barrier between levels: spawning threads per
  // level would cost more than a small level's work.
  std::barrier sync(t);
  auto work = [&](int id) {
    for (std::size_t l = 0; l + 1 < level_offsets_.size(); ++l) {
      const std::size_t begin = level_offsets_[l], size = level_offsets_[l + 1] - begin;
      const std::size_t from = begin + size * id / t, to = begin + size * (id + 1) / t;
      for (std::size_t i = from; i < to; ++i) {
        // Ring positions are scattered: prefetch a few nodes ahead so their
        // loads overlap instead of stalling one by one.
        const std::size_t ahead = i + kPrefetchDistance;
        if (ahead < to && cut.recovered(node_[ahead]))
          for (Index j = ring_offsets_[ahead]; j < ring_offsets_[ahead + 1]; ++j) __builtin_prefetch(&work_[ring_[j]]);
        if (!cut.recovered(node_[i])) continue;
        const std::span<const Index> ring(ring_.data() + ring_offsets_[i], ring_offsets_[i + 1] - ring_offsets_[i]);
        const std::span<const double> w(weights_.data() + ring_offsets_[i], ring.size());
        work_[m + i] = ring_frame(ring, w, work_, closed_[i] != 0).from_local(offset_[i]);
      }
      sync.arrive_and_wait();
    }
    // Back to the caller's order.
    const std::size_t n = node_.size();
    for (std::size_t i = n * id / t; i < n * (id + 1) / t; ++i)
      if (cut.recovered(node_[i])) x[vertex_[i]] = work_[m + i];
  };
  std::vector<std::jthread> team;
  for (int id = 1; id < t; ++id) team.emplace_back(work, id);
  work(0);
}

}  // namespace filigree
