// The adaptive cut's parts at scale (issue 10 item 5): the full cut made in
// O(n) and its lazily counted blockers, the indexed node queues, regions kept
// up to date incrementally (equal to a search from scratch), the region solver
// (dense and sparse factorisations against a plain solve), and the cut update
// (its regions, determinism across thread counts, bounded memory).

#include <algorithm>
#include <atomic>
#include <optional>
#include <random>
#include <set>
#include <stdexcept>

#include <Eigen/SparseCholesky>
#include <gtest/gtest.h>

#include "geometry/cotangent_laplacian.h"
#include "hierarchy/cut_state.h"
#include "hierarchy/hierarchy.h"
#include "preprocess/preprocess.h"
#include "runtime/cut.h"
#include "runtime/deformer.h"
#include "runtime/node_heap.h"
#include "runtime/procedural_motion.h"
#include "runtime/regions.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

// The plain reference, kept here as the whole-mesh test keeps its own solve:
// a depth-first search from each free vertex in ascending order, counting
// each adjacent cut vertex once per region, vertices sorted per region.
Regions plain_regions(const CotangentLaplacian& laplacian, const std::vector<bool>& in_cut) {
  const std::size_t n = laplacian.vertex_count();
  Regions out;
  out.region_of.assign(n, kNone);
  std::vector<Index> stack, seen_cut(n, kNone);
  for (Index seed = 0; seed < n; ++seed) {
    if (in_cut[seed] || out.region_of[seed] != kNone) continue;
    const Index r = static_cast<Index>(out.count());
    const std::size_t begin = out.vertices.size();
    Index constraints = 0;
    stack.assign(1, seed);
    out.region_of[seed] = r;
    while (!stack.empty()) {
      const Index v = stack.back();
      stack.pop_back();
      out.vertices.push_back(v);
      for (Index k = laplacian.offsets[v]; k < laplacian.offsets[v + 1]; ++k) {
        const Index j = laplacian.neighbors[k];
        if (in_cut[j]) {
          if (seen_cut[j] != r) seen_cut[j] = r, ++constraints;
        } else if (out.region_of[j] == kNone) {
          out.region_of[j] = r;
          stack.push_back(j);
        }
      }
    }
    std::sort(out.vertices.begin() + static_cast<std::ptrdiff_t>(begin), out.vertices.end());
    out.offsets.push_back(static_cast<Index>(out.vertices.size()));
    out.constraints.push_back(constraints);
  }
  return out;
}

struct Case {
  const char* name;
  TriMesh (*make)();
  std::size_t base_vertices;
};

class CutTest : public ::testing::TestWithParam<Case> {
 protected:
  void SetUp() override {
    mesh_ = GetParam().make();
    PreprocessOptions options;
    options.base_vertices = GetParam().base_vertices;
    h_ = preprocess(mesh_, options);
    graph_.emplace(h_);
    laplacian_ = cotangent_laplacian(mesh_);
  }
  // Regions compared field by field (region_of only where both have it).
  static void expect_equal(const Regions& got, const Regions& want, const std::string& when) {
    ASSERT_EQ(got.offsets, want.offsets) << when;
    ASSERT_EQ(got.vertices, want.vertices) << when;
    ASSERT_EQ(got.constraints, want.constraints) << when;
    if (got.count() > 0 || !got.region_of.empty()) {
      ASSERT_EQ(got.region_of, want.region_of) << when;
    }
    ASSERT_EQ(got.performance_estimate(), want.performance_estimate()) << when;
  }
  std::vector<Vec3> bent_result(double phase) {
    Deformer d(h_);
    return d.deform(procedural_pose(h_.base_mesh().positions, Motion::kBend, phase)).positions;
  }
  TriMesh mesh_;
  Hierarchy h_;
  std::optional<NodeGraph> graph_;  // of h_
  CotangentLaplacian laplacian_;
};

TEST_P(CutTest, TheFullCutIsEveryNodeRecovered) {
  CutState by_nodes(*graph_);
  for (NodeId k : recovery_order(h_)) by_nodes.recover(k);
  CutState full = CutState::full(h_, &*graph_);
  EXPECT_EQ(full.recovered_count(), by_nodes.recovered_count());
  EXPECT_EQ(full.alive_face_count(), by_nodes.alive_face_count());
  for (FaceId f = 0; f < h_.face_count(); ++f) ASSERT_EQ(full.face_alive(f), by_nodes.face_alive(f)) << "face " << f;
  EXPECT_EQ(full.mesh().faces, by_nodes.mesh().faces);
  // A cut that never changed holds no per-node counts.
  EXPECT_LE(full.memory_bytes(), (h_.node_count() + h_.face_count()) / 8 + 64);
  // Without the node graph it reads the same and refuses to change, unchanged.
  CutState read_only = CutState::full(h_);
  EXPECT_EQ(read_only.mesh().faces, full.mesh().faces);
  ASSERT_TRUE(full.can_remove(0));  // node 0 has no children: only the missing graph refuses it
  EXPECT_FALSE(read_only.can_remove(0));
  EXPECT_THROW(read_only.remove(0), std::logic_error);
  EXPECT_EQ(read_only.recovered_count(), h_.node_count());
  EXPECT_EQ(read_only.mesh().faces, full.mesh().faces);

  // The same random walk down and up from both: the same answers throughout.
  std::mt19937 rng(7);
  std::vector<NodeId> candidates;
  for (int move = 0; move < 3000; ++move) {
    const bool down = rng() % 3 != 0;
    candidates.clear();
    for (NodeId k = 0; k < h_.node_count(); ++k) {
      ASSERT_EQ(full.can_recover(k), by_nodes.can_recover(k)) << "move " << move << " node " << k;
      ASSERT_EQ(full.can_remove(k), by_nodes.can_remove(k)) << "move " << move << " node " << k;
      if (down ? full.can_remove(k) : full.can_recover(k)) candidates.push_back(k);
    }
    if (candidates.empty()) continue;
    const NodeId k = candidates[rng() % candidates.size()];
    if (down) {
      full.remove(k), by_nodes.remove(k);
    } else {
      full.recover(k), by_nodes.recover(k);
    }
    if (move % 10 == 0) {
      // Before the first change `full` answered without counts; now it has them.
      EXPECT_TRUE(full.memory_bytes() >= h_.node_count() * sizeof(Index));
    }
  }
  EXPECT_EQ(full.mesh().faces, by_nodes.mesh().faces);
}

TEST_P(CutTest, IncrementalRegionsEqualASearchFromScratch) {
  const std::size_t n = mesh_.vertex_count();
  std::mt19937 rng(11);
  for (int trial = 0; trial < 3; ++trial) {
    // Start from everything in the cut (an empty Regions), as the cut does.
    std::vector<bool> in_cut(n, true);
    Regions regions;
    std::vector<Index> changed;
    for (int step = 0; step < 60; ++step) {
      // Batches of flips, biased to free vertices early and to walls later,
      // so that regions grow, merge and split; some vertices flip twice.
      changed.clear();
      const std::size_t batch = 1 + rng() % (step % 7 == 0 ? n / 4 : 12);
      const double free_bias = step < 30 ? 0.7 : 0.4;
      for (std::size_t i = 0; i < batch; ++i) {
        const Index v = rng() % n;
        const bool want_free = std::uniform_real_distribution<>(0, 1)(rng) < free_bias;
        if (in_cut[v] != !want_free) {
          in_cut[v] = !want_free;
          changed.push_back(v);
        }
        if (i % 5 == 0 && !changed.empty()) {  // a vertex that changes back
          const Index u = changed[rng() % changed.size()];
          in_cut[u] = !in_cut[u];
          changed.push_back(u);
        }
      }
      update_regions(laplacian_, in_cut, changed, regions);
      const std::string when = "trial " + std::to_string(trial) + " step " + std::to_string(step);
      const Regions reference = plain_regions(laplacian_, in_cut);
      expect_equal(regions, reference, when);
      expect_equal(find_regions(laplacian_, in_cut), reference, when + " (from scratch)");
    }
  }
}

TEST_P(CutTest, RegionSolverMatchesAPlainSolvePerRegion) {
  const std::size_t n = mesh_.vertex_count();
  // Cuts with regions of one vertex up to well above the dense limit.
  std::mt19937 rng(3);
  const std::vector<Vec3> delta = laplacian_.apply(mesh_.positions);
  // One solver per thread count, so that factorisations run in parallel too.
  RegionSolver solver_1(laplacian_, delta), solver_2(laplacian_, delta);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  std::size_t kinds[3] = {0, 0, 0};
  for (double free_share : {0.1, 0.45, 0.6, 0.9}) {
    std::vector<bool> in_cut(n);
    for (Index v = 0; v < n; ++v) in_cut[v] = std::uniform_real_distribution<>(0, 1)(rng) >= free_share;
    const Regions regions = find_regions(laplacian_, in_cut);
    std::size_t direct = 0, dense = 0, sparse = 0;
    for (std::size_t r = 0; r < regions.count(); ++r) {
      const std::size_t m = regions.size(r);
      (m <= RegionSolver::kDirectMax ? direct : m <= RegionSolver::kDenseMax ? dense : sparse)++;
    }
    std::vector<Vec3> x = mesh_.positions;
    for (Vec3& p : x) p = rot * p + Vec3(0.1, 0.2, -0.3);
    std::vector<Vec3> want = x;
    // The plain reference: L_RR x_R = R δ_R + Σ w x_B per region, SimplicialLDLT.
    for (std::size_t r = 0; r < regions.count(); ++r) {
      const std::size_t m = regions.size(r);
      const Index* vs = regions.vertices.data() + regions.offsets[r];
      std::vector<Eigen::Triplet<double>> entries;
      Eigen::MatrixX3d b(static_cast<Eigen::Index>(m), 3);
      for (std::size_t i = 0; i < m; ++i) {
        const Index v = vs[i];
        Vec3 rhs = rot * delta[v];
        double diagonal = 0.0;
        for (Index k = laplacian_.offsets[v]; k < laplacian_.offsets[v + 1]; ++k) {
          const Index j = laplacian_.neighbors[k];
          diagonal += laplacian_.weights[k];
          if (in_cut[j]) {
            rhs += laplacian_.weights[k] * x[j];
          } else {
            const auto local = std::lower_bound(vs, vs + m, j) - vs;
            entries.emplace_back(static_cast<int>(i), static_cast<int>(local), -laplacian_.weights[k]);
          }
        }
        entries.emplace_back(static_cast<int>(i), static_cast<int>(i), diagonal);
        b.row(static_cast<Eigen::Index>(i)) = rhs.transpose();
      }
      Eigen::SparseMatrix<double> a(static_cast<int>(m), static_cast<int>(m));
      a.setFromTriplets(entries.begin(), entries.end());
      Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(a);
      ASSERT_EQ(ldlt.info(), Eigen::Success);
      const Eigen::MatrixX3d sol = ldlt.solve(b);
      for (std::size_t i = 0; i < m; ++i) want[vs[i]] = sol.row(static_cast<Eigen::Index>(i)).transpose();
    }
    const double diag = bounding_box_diagonal(mesh_.positions);
    for (int threads : {1, 2}) {
      RegionSolver& solver = threads == 1 ? solver_1 : solver_2;
      for (int round = 0; round < 2; ++round) {
        std::vector<Vec3> got = x;
        const std::size_t made = solver.solve(regions, got, threads, [&](Index) { return rot; });
        // Regions the previous cut also had keep their factorisation; a
        // second solve reuses every one.
        if (round == 0) {
          EXPECT_LE(made, dense + sparse);
        } else {
          EXPECT_EQ(made, 0u);
        }
        double worst = 0.0;
        for (Index v = 0; v < n; ++v) worst = std::max(worst, (got[v] - want[v]).norm());
        EXPECT_LE(worst, 1e-9 * diag) << "free share " << free_share << ", " << direct << " direct, " << dense
                                      << " dense and " << sparse << " sparse regions, " << threads << " threads";
      }
      EXPECT_EQ(solver.cached_factorizations(), dense + sparse);
    }
    kinds[0] += direct, kinds[1] += dense, kinds[2] += sparse;
  }
  EXPECT_GT(kinds[0], 0u);
  EXPECT_GT(kinds[1], 0u);
  EXPECT_GT(kinds[2], 0u);
}

// A rotation with a prefetch member is told the vertices ahead; results are
// the same as without.
struct CountingRotation {
  Eigen::Matrix3d r;
  std::atomic<std::size_t>* hints;
  Eigen::Matrix3d operator()(Index) const { return r; }
  void prefetch(Index) const { ++*hints; }
};

TEST_P(CutTest, RotationPrefetchHintsChangeNothing) {
  const std::size_t n = mesh_.vertex_count();
  std::vector<bool> in_cut(n);
  std::mt19937 rng(9);
  for (Index v = 0; v < n; ++v) in_cut[v] = rng() % 4 != 0;  // mostly tiny regions
  const Regions regions = find_regions(laplacian_, in_cut);
  const std::vector<Vec3> delta = laplacian_.apply(mesh_.positions);
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(-0.3, Vec3(0, 1, 1).normalized()).toRotationMatrix();
  RegionSolver plain(laplacian_, delta), hinted(laplacian_, delta);
  std::vector<Vec3> a = mesh_.positions, b = mesh_.positions;
  plain.solve(regions, a, 2, [&](Index) { return rot; });
  std::atomic<std::size_t> hints{0};
  hinted.solve(regions, b, 2, CountingRotation{rot, &hints});
  EXPECT_EQ(a, b);
  EXPECT_GT(hints.load(), 0u);
}

TEST_P(CutTest, UpdatedCutKeepsItsRegionsExactAndItsStateBounded) {
  const std::vector<Vec3> bent = bent_result(1.0);
  for (double t : {500.0, 2e4, 3e5}) {
    AdaptiveCut cut(*graph_, laplacian_, t);
    EXPECT_EQ(cut.regions().count(), 0u);
    for (int frame = 0; frame < 25; ++frame) {
      cut.update(bent, 64 + h_.node_count() / 8, 16 + h_.node_count() / 64);
      const std::string when = "T = " + std::to_string(t) + " frame " + std::to_string(frame);
      const CutState& s = cut.state();
      for (Index v = 0; v < mesh_.vertex_count(); ++v) ASSERT_EQ(cut.in_cut()[v], s.vertex_present(v)) << when;
      expect_equal(cut.regions(), plain_regions(laplacian_, cut.in_cut()), when);
      EXPECT_LE(cut.regions().performance_estimate(), t) << when;
    }
    // Queues hold each node at most once, whatever the frame count.
    EXPECT_LE(cut.memory_bytes(), 40 * mesh_.vertex_count() + 4096) << "T = " << t;
  }
  // T = 0 holds about two bits per node and vertex, one per face.
  AdaptiveCut direct(*graph_, laplacian_, 0.0);
  EXPECT_LE(direct.memory_bytes(), mesh_.vertex_count() / 2 + h_.face_count() / 8 + 256);
  EXPECT_EQ(direct.state().recovered_count(), h_.node_count());
}

TEST_P(CutTest, ThresholdChangesResetOrKeepTheCut) {
  const std::vector<Vec3> bent = bent_result(1.0);
  const std::size_t eval = 64 + h_.node_count() / 8, moves = 16 + h_.node_count() / 64;
  AdaptiveCut cut(*graph_, laplacian_, 2e4);
  for (int frame = 0; frame < 5; ++frame) cut.update(bent, eval, moves);
  ASSERT_GT(cut.regions().count(), 0u);
  // Finite to finite keeps the cut.
  const std::vector<bool> before = cut.in_cut();
  cut.set_threshold(3e4);
  EXPECT_EQ(cut.in_cut(), before);
  // T = 0: the full cut, no regions, nothing per node kept.
  cut.set_threshold(0.0);
  EXPECT_EQ(cut.state().recovered_count(), h_.node_count());
  EXPECT_EQ(cut.regions().count(), 0u);
  EXPECT_EQ(cut.update(bent, eval, moves), 0u);
  EXPECT_LE(cut.memory_bytes(), mesh_.vertex_count() / 2 + h_.face_count() / 8 + 256);
  // T = ∞: the empty cut, one region per component of the removed vertices.
  cut.set_threshold(AdaptiveCut::kInfinity);
  EXPECT_EQ(cut.state().recovered_count(), 0u);
  expect_equal(cut.regions(), plain_regions(laplacian_, cut.in_cut()), "T = inf");
  // Back to a finite T: the cut starts full again and adapts.
  cut.set_threshold(2e4);
  EXPECT_EQ(cut.state().recovered_count(), h_.node_count());
  for (int frame = 0; frame < 5; ++frame) cut.update(bent, eval, moves);
  EXPECT_GT(cut.regions().count(), 0u);
  expect_equal(cut.regions(), plain_regions(laplacian_, cut.in_cut()), "T = 2e4 again");
}

// Optimisation goes where the deformation is acute: under a local bump the
// vertices handed to regions are the ones the bump moved, not the still
// parts (with the most acute node taken first; taking the mildest, the
// regions settle where nothing moved).
TEST_P(CutTest, RegionsGoWhereTheDeformationIsAcute) {
  Deformer d(h_);
  const std::vector<Vec3> bumped = d.deform(procedural_pose(h_.base_mesh().positions, Motion::kBump, 1.0)).positions;
  // How far each vertex moved: 0 away from the bump.
  std::vector<double> moved(mesh_.vertex_count());
  double mean_all = 0.0;
  for (Index v = 0; v < mesh_.vertex_count(); ++v) mean_all += moved[v] = (bumped[v] - mesh_.positions[v]).norm();
  mean_all /= static_cast<double>(mesh_.vertex_count());
  AdaptiveCut cut(*graph_, laplacian_, 2e4);
  for (int frame = 0; frame < 20; ++frame) cut.update(bumped, h_.node_count(), 16 + h_.node_count() / 64);
  double mean_regions = 0.0;
  std::size_t in_regions = 0;
  for (Index v = 0; v < mesh_.vertex_count(); ++v)
    if (!cut.in_cut()[v]) mean_regions += moved[v], ++in_regions;
  ASSERT_GT(in_regions, 0u);
  mean_regions /= static_cast<double>(in_regions);
  EXPECT_GT(mean_regions, 2.0 * mean_all) << in_regions << " vertices in regions, moved " << mean_regions
                                          << " on average; the whole mesh " << mean_all;
}

// On an unchanged pose the cut settles and stays settled: converged() once
// a full round of scoring moved nothing, and 50 further frames move nothing.
TEST_P(CutTest, OnAnUnchangedPoseTheCutSettlesAndStays) {
  const std::vector<Vec3> bumped =
      Deformer(h_).deform(procedural_pose(h_.base_mesh().positions, Motion::kBump, 1.0)).positions;
  const std::size_t eval = 64 + h_.node_count() / 16, moves = 16 + h_.node_count() / 100;
  AdaptiveCut cut(*graph_, laplacian_, 2e4);
  EXPECT_FALSE(cut.converged());
  int frames = 0;
  std::size_t moved = 0;
  for (; frames < 2000 && !cut.converged(); ++frames) moved += cut.update(bumped, eval, moves);
  ASSERT_TRUE(cut.converged()) << "not settled after " << frames << " frames";
  EXPECT_GT(moved, 0u) << "the bump moved nothing: the test sees nothing";
  // A round of scoring (1/16 of the vertices a frame) without a move: at least 16 frames.
  const std::vector<bool> settled = cut.in_cut();
  for (int more = 0; more < 50; ++more) {
    ASSERT_EQ(cut.update(bumped, eval, moves), 0u) << "frame " << frames + more;
    ASSERT_TRUE(cut.converged());
  }
  EXPECT_EQ(cut.in_cut(), settled);
  // A new T gives the cut somewhere to go: not converged until it has looked again.
  cut.set_threshold(4e4);
  EXPECT_FALSE(cut.converged());
  // T = 0 and T = ∞ never move.
  EXPECT_TRUE(AdaptiveCut(*graph_, laplacian_, 0.0).converged());
  EXPECT_TRUE(AdaptiveCut(*graph_, laplacian_, AdaptiveCut::kInfinity).converged());
}

TEST_P(CutTest, CutMovesDoNotDependOnTheThreadCount) {
  const std::vector<Vec3> bent = bent_result(0.8);
  AdaptiveCut one(*graph_, laplacian_, 2e4), two(*graph_, laplacian_, 2e4);
  for (int frame = 0; frame < 10; ++frame) {
    const std::size_t eval = 64 + h_.node_count() / 16, moves = 16 + h_.node_count() / 100;
    ASSERT_EQ(one.update(bent, eval, moves, 1), two.update(bent, eval, moves, 2)) << "frame " << frame;
    ASSERT_EQ(one.in_cut(), two.in_cut()) << "frame " << frame;
    for (NodeId k = 0; k < h_.node_count(); ++k) ASSERT_EQ(one.score(k), two.score(k));
  }
}

// The cut depends on its history (it moves a bounded number of nodes a frame
// by remembered scores), so a session moved to another process carries it:
// restored, it moves exactly as the original would have.
TEST_P(CutTest, ARestoredCutContinuesAsTheOriginalWould) {
  const std::size_t eval = 64 + h_.node_count() / 16, moves = 16 + h_.node_count() / 100;
  AdaptiveCut original(*graph_, laplacian_, 2e4);
  for (int frame = 0; frame < 6; ++frame) original.update(bent_result(0.2 * frame), eval, moves);
  ASSERT_GT(original.regions().count(), 0u);
  const CutSnapshot snapshot = original.snapshot();
  ASSERT_FALSE(snapshot.empty());
  EXPECT_LT(snapshot.unrecovered.size(), h_.node_count() / 2);

  AdaptiveCut restored(*graph_, laplacian_, 2e4), fresh(*graph_, laplacian_, 2e4);
  restored.restore(snapshot);
  ASSERT_EQ(restored.in_cut(), original.in_cut());
  expect_equal(restored.regions(), original.regions(), "restored");
  const CutSnapshot again = restored.snapshot();
  EXPECT_EQ(again.unrecovered, snapshot.unrecovered);
  EXPECT_EQ(again.scores, snapshot.scores);
  EXPECT_EQ(again.next_block, snapshot.next_block);

  bool fresh_differs = false;
  for (int frame = 6; frame < 12; ++frame) {
    const std::vector<Vec3> x = bent_result(0.15 * frame);
    const std::string when = "frame " + std::to_string(frame);
    ASSERT_EQ(restored.update(x, eval, moves), original.update(x, eval, moves)) << when;
    ASSERT_EQ(restored.in_cut(), original.in_cut()) << when;
    expect_equal(restored.regions(), original.regions(), when);
    for (NodeId k = 0; k < h_.node_count(); ++k) ASSERT_EQ(restored.score(k), original.score(k)) << when;
    fresh.update(x, eval, moves);
    fresh_differs |= fresh.in_cut() != original.in_cut();
  }
  // The finding behind carrying it: a cut started over is not the same cut.
  EXPECT_TRUE(fresh_differs);
}

TEST_P(CutTest, ASnapshotOfAnotherMeshIsRefused) {
  AdaptiveCut cut(*graph_, laplacian_, 2e4);
  CutSnapshot wrong;
  wrong.scores.assign(h_.node_count() + 1, 1.0f);
  EXPECT_THROW(cut.restore(wrong), std::invalid_argument);
  // Not a cut: a node whose children are recovered cannot leave it.
  CutSnapshot parent_only;
  parent_only.scores.assign(h_.node_count(), 0.0f);
  for (NodeId k = 0; k < h_.node_count() && parent_only.unrecovered.empty(); ++k)
    if (!graph_->children_of(k).empty()) parent_only.unrecovered.push_back(k);
  ASSERT_FALSE(parent_only.unrecovered.empty());
  EXPECT_THROW(cut.restore(parent_only), std::invalid_argument);
  EXPECT_EQ(cut.state().recovered_count(), h_.node_count());  // left full
  // Without an adaptive T there is nothing to restore.
  AdaptiveCut direct(*graph_, laplacian_, 0.0);
  EXPECT_TRUE(direct.snapshot().empty());
  direct.restore(wrong);
  EXPECT_EQ(direct.state().recovered_count(), h_.node_count());
}

// What a session does after a restore: the recorded pose deformed with the
// restored cut is the old process's last frame, and later frames match.
TEST_P(CutTest, ADeformerWithARestoredCutGivesTheOriginalsFrames) {
  DeformerOptions o;
  o.threshold = 2e4;
  const auto pose = [&](int frame) { return procedural_pose(h_.base_mesh().positions, Motion::kBend, 0.15 * frame); };
  Deformer original(h_, o);
  std::vector<Vec3> last;
  for (int frame = 0; frame < 6; ++frame) last = original.deform(pose(frame)).positions;
  Deformer restored(h_, o), fresh(h_, o);
  restored.restore_cut(original.cut_snapshot());
  const std::vector<Vec3> again = restored.deform(pose(5)).positions;
  const double diagonal = bounding_box_diagonal(h_.rest_positions);
  const auto worst = [](const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
    double w = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) w = std::max(w, (a[i] - b[i]).cwiseAbs().maxCoeff());
    return w;
  };
  EXPECT_LE(worst(again, last), 1e-12 * diagonal);
  double fresh_gap = 0.0;
  fresh.deform(pose(5));
  for (int frame = 6; frame < 10; ++frame) {
    const DeformResult want = original.deform(pose(frame)), got = restored.deform(pose(frame));
    EXPECT_EQ(got.stats.cut_nodes, want.stats.cut_nodes) << frame;
    EXPECT_LE(worst(got.positions, want.positions), 1e-12 * diagonal) << frame;
    fresh_gap = std::max(fresh_gap, worst(fresh.deform(pose(frame)).positions, want.positions));
  }
  // Started over, the frames differ by more than a frame's quantization
  // error (the server's automatic target is 5e-5 of the diagonal).
  EXPECT_GT(fresh_gap, 5e-5 * diagonal);
}

TriMesh bunny() { return test::shipped_mesh("bunny_small.obj"); }
TriMesh grid() { return test::wavy_grid(30); }
TriMesh spheres() { return test::two_spheres(3); }

INSTANTIATE_TEST_SUITE_P(Meshes, CutTest,
                         ::testing::Values(Case{"bunny", bunny, 150}, Case{"open_grid", grid, 60},
                                           Case{"two_spheres", spheres, 80}),
                         [](const auto& info) { return std::string(info.param.name); });

// The indexed heap against an ordered set, under pushes, re-keys and erases.
TEST(NodeHeapTest, MatchesAnOrderedSet) {
  std::mt19937 rng(5);
  const std::size_t n = 400;
  std::vector<float> key(n, 0.0f);
  std::vector<Index> place(n, kNone);
  struct Before {
    bool operator()(const HeapEntry& a, const HeapEntry& b) const {
      return a.key != b.key ? a.key < b.key : a.node < b.node;
    }
  };
  NodeHeap<Before> heap(place);
  auto cmp = [&](NodeId a, NodeId b) { return key[a] != key[b] ? key[a] < key[b] : a < b; };
  std::set<NodeId, decltype(cmp)> want(cmp);
  for (int op = 0; op < 20000; ++op) {
    const NodeId k = rng() % n;
    const int what = rng() % 3;
    if (what == 0 && !heap.contains(k)) {
      key[k] = static_cast<float>(rng() % 50);
      heap.push(k, key[k]);
      want.insert(k);
    } else if (what == 1 && heap.contains(k)) {
      want.erase(k);
      key[k] = static_cast<float>(rng() % 50);  // ties are common
      heap.update(k, key[k]);
      want.insert(k);
    } else if (what == 2 && heap.contains(k)) {
      heap.erase(k);
      want.erase(k);
    }
    ASSERT_EQ(heap.size(), want.size());
    if (!want.empty()) {
      ASSERT_EQ(heap.top().node, *want.begin()) << "op " << op;
      ASSERT_EQ(heap.top().key, key[*want.begin()]);
    }
  }
}

}  // namespace
}  // namespace filigree
