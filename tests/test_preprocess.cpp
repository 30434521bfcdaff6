// Preprocessing: the hierarchy, its cuts, the MAPS parameterisation and the
// ring coordinates, over meshes of different topology.

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <map>
#include <optional>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "geometry/cotangent_laplacian.h"
#include "geometry/ring_frame.h"
#include "hierarchy/cut_state.h"
#include "hierarchy/node_graph.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/mesh_validation.h"
#include "preprocess/mean_curvature.h"
#include "preprocess/mesh_saliency.h"
#include "preprocess/preprocess.h"
#include "runtime/deformer_model.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

struct Case {
  std::string name;
  std::function<TriMesh()> make;
  std::size_t base_vertices;
};

// Bounds on the distance between a vertex and its MAPS image on the base rest
// mesh, in mean base edge lengths.
constexpr double kMapsMaxError = 0.5;
constexpr double kMapsRmsError = 0.2;

std::ostream& operator<<(std::ostream& os, const Case& c) { return os << c.name; }

// Everything the test compares between cut meshes: Euler characteristic,
// boundary loops, components; fails the test if the mesh is not a clean
// manifold.
struct Topology {
  long euler = 0;
  std::size_t boundary_loops = 0, components = 0;
  bool operator==(const Topology&) const = default;
};

Topology topology_of(const TriMesh& m, const std::string& when) {
  const ValidationReport r = validate_mesh(m);
  EXPECT_FALSE(r.fatal()) << when << "\n" << r.to_string();
  EXPECT_EQ(r.degenerate_faces.count, 0u) << when;
  EXPECT_EQ(r.duplicate_faces.count, 0u) << when;
  EXPECT_EQ(r.unreferenced_vertices.count, 0u) << when;
  std::set<std::pair<Index, Index>> edges;
  for (const Triangle& f : m.faces)
    for (int c = 0; c < 3; ++c) edges.insert(std::minmax(f[c], f[(c + 1) % 3]));
  return {static_cast<long>(m.vertex_count()) - static_cast<long>(edges.size()) + static_cast<long>(m.face_count()),
          r.boundary_loops, r.components};
}

class PreprocessTest : public ::testing::TestWithParam<Case> {
 protected:
  static void SetUpTestSuite() {}
  void SetUp() override {
    mesh_ = GetParam().make();
    PreprocessOptions options;
    options.base_vertices = GetParam().base_vertices;
    options.threads = 2;
    h_ = preprocess(mesh_, options);
    graph_.emplace(h_);
  }
  TriMesh mesh_;
  Hierarchy h_;
  std::optional<NodeGraph> graph_;  // of h_
};

TEST_P(PreprocessTest, ReachesTheTargetAndKeepsTopologyInTheBase) {
  EXPECT_EQ(h_.vertex_count(), mesh_.vertex_count());
  EXPECT_EQ(h_.base_vertices.size() + h_.node_count(), mesh_.vertex_count());
  // Small meshes may stop a little above the target when no removal is valid.
  EXPECT_LE(h_.base_vertices.size(), GetParam().base_vertices * 11 / 10 + 4);
  EXPECT_EQ(topology_of(h_.base_mesh(), "base"), topology_of(mesh_, "original"));
}

TEST_P(PreprocessTest, RecoveringEveryNodeGivesBackTheOriginalTriangles) {
  CutState cut(*graph_);
  for (NodeId k : recovery_order(h_)) cut.recover(k);
  std::vector<Index> ids;
  const TriMesh full = cut.mesh(&ids);
  ASSERT_EQ(full.vertex_count(), mesh_.vertex_count());
  for (Index i = 0; i < ids.size(); ++i) ASSERT_EQ(ids[i], i);
  EXPECT_EQ(full.positions, mesh_.positions);
  EXPECT_EQ(full.faces, mesh_.faces);  // same triangles, same corner order, same face order
}

TEST_P(PreprocessTest, EveryIntermediateCutIsAManifoldWithTheOriginalTopology) {
  const Topology original = topology_of(mesh_, "original");
  CutState cut(*graph_);
  const std::vector<NodeId> order = recovery_order(h_);
  const std::size_t step = std::max<std::size_t>(order.size() / 150, 1);
  for (std::size_t i = 0; i < order.size(); ++i) {
    cut.recover(order[i]);
    if (i % step == 0 || i + 1 == order.size()) {
      ASSERT_EQ(topology_of(cut.mesh(), "after recovering " + std::to_string(i + 1) + " nodes"), original);
    }
  }
}

// Random valid cuts, going up and down the hierarchy: the cut mesh stays a
// manifold with the same topology, and any node that may be recovered finds
// its whole removal-time ring present.
TEST_P(PreprocessTest, RandomCutsAreManifoldAndRecoverableNodesHaveTheirRing) {
  const Topology original = topology_of(mesh_, "original");
  std::mt19937 rng(12345);
  CutState cut(*graph_);
  const std::size_t moves = std::min<std::size_t>(4 * h_.node_count(), 6000);
  std::size_t checked_rings = 0;
  std::vector<NodeId> candidates;
  for (std::size_t move = 0; move < moves; ++move) {
    // Three recoveries for one removal on average, so the walk reaches deep cuts.
    const bool up = rng() % 4 != 0;
    candidates.clear();
    for (NodeId k = 0; k < h_.node_count(); ++k)
      if (up ? cut.can_recover(k) : cut.can_remove(k)) candidates.push_back(k);
    if (candidates.empty()) continue;
    const NodeId k = candidates[rng() % candidates.size()];
    if (up) {
      for (Index v : h_.ring(k)) ASSERT_TRUE(cut.vertex_present(v)) << "node " << k << " ring vertex " << v;
      ++checked_rings;
      cut.recover(k);
      // After recovery the node's vertex is present with its fan.
      ASSERT_TRUE(cut.vertex_present(h_.node_vertex[k]));
      for (FaceId f : graph_->removed_faces_of(k)) ASSERT_TRUE(cut.face_alive(f));
    } else {
      cut.remove(k);
      ASSERT_FALSE(cut.vertex_present(h_.node_vertex[k]));
    }
    if (move % 97 == 0) {
      ASSERT_EQ(topology_of(cut.mesh(), "random cut at move " + std::to_string(move)), original);
      for (NodeId j = 0; j < h_.node_count(); ++j) {
        if (!cut.can_recover(j)) continue;
        for (Index v : h_.ring(j)) ASSERT_TRUE(cut.vertex_present(v)) << "node " << j << " ring vertex " << v;
      }
    }
  }
  EXPECT_GT(checked_rings, h_.node_count());
  // Recovering a node whose parent is missing, or removing one never recovered, is refused.
  CutState empty(*graph_);
  NodeId with_parent = 0;
  while (with_parent < h_.node_count() && graph_->parents_of(with_parent).empty()) ++with_parent;
  ASSERT_LT(with_parent, h_.node_count());
  EXPECT_THROW(empty.recover(with_parent), std::logic_error);
  EXPECT_THROW(empty.remove(0), std::logic_error);
}

TEST_P(PreprocessTest, ParentsWereRemovedAfterTheirChildren) {
  std::size_t edges = 0, child_edges = 0;
  for (NodeId k = 0; k < h_.node_count(); ++k) {
    for (NodeId p : graph_->parents_of(k)) {
      EXPECT_GT(p, k);
      const auto kids = graph_->children_of(p);
      EXPECT_TRUE(std::find(kids.begin(), kids.end(), k) != kids.end());
      ++edges;
    }
    child_edges += graph_->children_of(k).size();
  }
  EXPECT_GT(edges, 0u);
  EXPECT_EQ(edges, child_edges);  // every child edge, once each way
  EXPECT_GT(h_.depth(), 1u);
}

// The node graph against a search of its own: slot i of node k holds the
// one face ever made on fan_face(k, i)'s corners, and k's children are the
// creators of those faces; on one thread or several (the ranges split
// inside the created faces), the same.
TEST_P(PreprocessTest, NodeGraphMatchesABruteForceSearchOnAnyNumberOfThreads) {
  std::map<std::array<Index, 3>, FaceId> by_corners;
  h_.for_each_face([&](FaceId f, Triangle t) {
    std::sort(t.begin(), t.end());
    ASSERT_TRUE(by_corners.emplace(t, f).second) << "two faces on the corners of face " << f;
  });
  for (std::size_t threads : {1u, 2u, 3u}) {
    const NodeGraph g(h_, threads);
    for (NodeId k = 0; k < h_.node_count(); ++k) {
      std::vector<NodeId> children;
      ASSERT_EQ(g.removed_faces_of(k).size(), h_.fan_size(k));
      for (std::size_t i = 0; i < h_.fan_size(k); ++i) {
        Triangle t = h_.fan_face(k, i);
        std::sort(t.begin(), t.end());
        const auto found = by_corners.find(t);
        ASSERT_NE(found, by_corners.end()) << "node " << k << " slot " << i;
        ASSERT_EQ(g.removed_faces_of(k)[i], found->second) << "node " << k << " slot " << i << ", " << threads << " threads";
        if (const NodeId c = h_.creator(found->second); c != kNone) children.push_back(c);
      }
      std::sort(children.begin(), children.end());
      children.erase(std::unique(children.begin(), children.end()), children.end());
      ASSERT_TRUE(std::ranges::equal(g.children_of(k), children)) << "node " << k << ", " << threads << " threads";
    }
  }
}

// The MAPS image of every vertex on the base rest mesh stays within a fraction
// of the base mesh's mean edge length of the vertex: the base is a faithful
// approximation at its own resolution, on every kind of mesh.
TEST_P(PreprocessTest, MapsCoordinatesLandNearTheOriginalOnTheBaseMesh) {
  const TriMesh base = h_.base_mesh();
  double base_edge = 0.0;
  for (const Triangle& f : base.faces)
    for (int c = 0; c < 3; ++c) base_edge += (base.positions[f[c]] - base.positions[f[(c + 1) % 3]]).norm();
  base_edge /= 3.0 * static_cast<double>(base.face_count());
  double max_error = 0.0, sum_sq = 0.0;
  for (Index v = 0; v < h_.vertex_count(); ++v) {
    const Vec3 b = h_.maps_barycentric(v);
    ASSERT_GE(b.minCoeff(), 0.0);
    ASSERT_NEAR(b.sum(), 1.0, 1e-12);
    const double e = (h_.maps_position(v, h_.rest_positions) - h_.rest_positions[v]).norm() / base_edge;
    max_error = std::max(max_error, e);
    sum_sq += e * e;
    if (graph_->node_of_vertex(v) == kNone) {
      ASSERT_LT(e, 1e-12) << "base vertex " << v << " must map to itself";
    }
  }
  const double rms = std::sqrt(sum_sq / static_cast<double>(h_.vertex_count()));
  std::printf("[ maps     ] %s: max %.3f, rms %.3f base edge lengths (base edge %.4g of the bbox diagonal)\n",
              GetParam().name.c_str(), max_error, rms, base_edge / bounding_box_diagonal(mesh_.positions));
  EXPECT_LE(max_error, kMapsMaxError);
  EXPECT_LE(rms, kMapsRmsError);
}

// Direct recovery (thesis eq. 3.10) from the rest positions of the ring puts
// every removed vertex back: the stored offset is in the frame of the stored
// (16-bit) weights, so only the offset's own float rounding remains — a
// few 1e-8 of the ring's radius (the runtime adds back even that).
TEST_P(PreprocessTest, RingCoordinatesReproduceTheRestPosition) {
  for (NodeId k = 0; k < h_.node_count(); ++k) {
    const RingFrame frame = ring_frame(h_.ring(k), h_.weights(k), h_.rest_positions, h_.node_closed[k] != 0);
    const Vec3 offset = h_.node_offset[k].cast<double>();
    const Vec3 back = frame.from_local(offset);
    ASSERT_LT((back - h_.rest_positions[h_.node_vertex[k]]).norm(), 2e-7 * frame.scale * (1.0 + offset.norm())) << "node " << k;
    double sum = 0.0;
    for (std::uint16_t w : h_.weights(k)) sum += w;
    ASSERT_NEAR(sum / 65535.0, 1.0, static_cast<double>(h_.ring_size(k)) / 65535.0);  // each rounded by ≤ a step
  }
}

// The offsets were computed against the rounded weights: each is exactly the
// float rounding of the offset in the frame of the stored weights. (Against
// the double weights they came from, nearly every offset would differ in its
// last bit.)
TEST_P(PreprocessTest, RingOffsetsAreExactForTheStoredWeights) {
  std::size_t differ = 0;
  for (NodeId k = 0; k < h_.node_count(); ++k) {
    const RingFrame frame = ring_frame(h_.ring(k), h_.weights(k), h_.rest_positions, h_.node_closed[k] != 0);
    const Vec3f exact = frame.to_local(h_.rest_positions[h_.node_vertex[k]]).cast<float>();
    differ += exact == h_.node_offset[k] ? 0 : 1;
  }
  EXPECT_EQ(differ, 0u);
}

TEST_P(PreprocessTest, DifferentialCoordinatesAreTheCotangentLaplacianOfTheRestMesh) {
  // Not stored in the hierarchy: the deformer model derives δ = L x_rest.
  // Never NaN; on any mesh Σ δ_i = 0 (L is symmetric with zero row sums).
  const auto model = DeformerModel::create(std::make_shared<const Hierarchy>(h_));
  const std::vector<Vec3>& delta = model->differential_coordinates();
  ASSERT_EQ(delta.size(), h_.vertex_count());
  EXPECT_EQ(delta, cotangent_laplacian(mesh_).apply(mesh_.positions));
  Vec3 sum = Vec3::Zero();
  for (const Vec3& d : delta) {
    ASSERT_TRUE(d.allFinite());
    sum += d;
  }
  EXPECT_LT(sum.norm(), 1e-9 * bounding_box_diagonal(mesh_.positions) * static_cast<double>(h_.vertex_count()));
}

INSTANTIATE_TEST_SUITE_P(
    Meshes, PreprocessTest,
    ::testing::Values(Case{"bunny_small_real", [] { return test::shipped_mesh("bunny_small.obj"); }, 150},
                      Case{"head_open_boundary", [] { return test::shipped_mesh("head_open.off"); }, 200},
                      Case{"two_spheres_components", [] { return test::two_spheres(3); }, 80},
                      Case{"torus_genus1", [] { return test::torus(40, 16); }, 60},
                      Case{"wavy_grid_boundary", [] { return test::wavy_grid(30); }, 80}),
    [](const ::testing::TestParamInfo<Case>& info) { return info.param.name; });

TEST(PreprocessInput, RefusesBrokenMeshesWithAClearMessage) {
  TriMesh nan_mesh = test::icosphere(1);
  nan_mesh.positions[5].x() = std::nan("");
  try {
    preprocess(nan_mesh, {});
    FAIL() << "NaN accepted";
  } catch (const InvalidMeshError& e) {
    EXPECT_NE(std::string(e.what()).find("NaN"), std::string::npos) << e.what();
  }
  TriMesh empty;
  EXPECT_THROW(preprocess(empty, {}), InvalidMeshError);
  TriMesh bad_index = test::icosphere(1);
  bad_index.faces[3][1] = 10000;
  EXPECT_THROW(preprocess(bad_index, {}), InvalidMeshError);
}

TEST(PreprocessInput, RejectsBadBaseSizes) {
  const TriMesh m = test::icosphere(2);
  PreprocessOptions both;
  both.base_vertices = 20;
  both.ratio = 0.1;
  EXPECT_THROW(preprocess(m, both), std::invalid_argument);
  PreprocessOptions zero;
  zero.ratio = 0.0;
  EXPECT_THROW(preprocess(m, zero), std::invalid_argument);
}

TEST(PreprocessInput, RatioAndDefaultTargets) {
  const TriMesh m = test::icosphere(3);  // 642 vertices
  PreprocessOptions ratio;
  ratio.ratio = 0.1;
  EXPECT_EQ(preprocess(m, ratio).base_vertices.size(), 64u);
  EXPECT_EQ(default_base_vertices(1000000), 5000u);
  EXPECT_EQ(default_base_vertices(50000), 1000u);
  EXPECT_EQ(default_base_vertices(642), 100u);
}

// A base smaller than the mesh allows is not silently larger: the report
// says, for every vertex left, which check kept it.
TEST(PreprocessInput, ABaseAboveTheTargetSaysWhatKeptEachVertex) {
  const TriMesh m = test::two_spheres(2);
  PreprocessOptions o;
  o.base_vertices = 4;  // two closed spheres cannot go below 4 vertices each
  SimplifyReport report;
  o.simplify.report = &report;
  const Hierarchy h = preprocess(m, o);
  ASSERT_GT(h.base_vertices.size(), 4u);
  std::size_t held = 0;
  for (const std::size_t n : report.refused) held += n;
  EXPECT_EQ(held, h.base_vertices.size());
  EXPECT_GT(report.refused[static_cast<std::size_t>(BaseRefusal::kTopology)], 0u);
  // A target within reach leaves the report empty.
  SimplifyReport none;
  o.base_vertices = 200;
  o.simplify.report = &none;
  EXPECT_EQ(preprocess(m, o).base_vertices.size(), 200u);
  for (const std::size_t n : none.refused) EXPECT_EQ(n, 0u);
}

// Saliency keeps what stands out: the vertices of highest saliency (on a
// sphere with a spike, whose curvature differs from what surrounds it) are
// removed later with the saliency term in the removal cost than without it.
// A stop asked while saliency runs skips the clusters left (about a second
// at 2M vertices with no other check): with the flag already set, none is
// computed and every vertex comes out 0, where the spiked sphere has salient ones.
TEST(PreprocessSaliency, AStopSkipsTheClustersLeft) {
  TriMesh m = test::icosphere(4);
  for (Vec3& p : m.positions)
    if (p.normalized().z() > 0.95) p *= 1.3;
  const std::vector<double> h = mean_curvature(m, cotangent_laplacian(m), std::vector<bool>(m.vertex_count(), false));
  const std::atomic<bool> stop{true};
  const std::vector<double> stopped = mesh_saliency(m, h, 2, &stop), whole = mesh_saliency(m, h, 2);
  EXPECT_EQ(*std::max_element(stopped.begin(), stopped.end()), 0.0);
  EXPECT_GT(*std::max_element(whole.begin(), whole.end()), 0.5);
}

TEST(PreprocessSaliency, SalientVerticesAreRemovedLater) {
  TriMesh m = test::icosphere(4);
  for (Vec3& p : m.positions) {
    const double from_pole = std::acos(std::clamp(p.normalized().z(), -1.0, 1.0));
    if (from_pole < 0.3) p *= 1.0 + 0.35 * (1.0 - from_pole / 0.3);
  }
  const std::vector<double> saliency =
      mesh_saliency(m, mean_curvature(m, cotangent_laplacian(m), std::vector<bool>(m.vertex_count(), false)), 1);
  std::vector<Index> salient(m.vertex_count());
  for (Index v = 0; v < m.vertex_count(); ++v) salient[v] = v;
  const std::size_t top = m.vertex_count() / 20;  // the most salient 5%
  std::partial_sort(salient.begin(), salient.begin() + top, salient.end(),
                    [&](Index a, Index b) { return saliency[a] != saliency[b] ? saliency[a] > saliency[b] : a < b; });
  salient.resize(top);
  // When each of them left: its place in the removal order (base vertices never did).
  auto mean_removal = [&](double saliency_weight) {
    PreprocessOptions o;
    o.base_vertices = 100;
    o.simplify.saliency_weight = saliency_weight;
    const Hierarchy h = preprocess(m, o);
    std::vector<double> removed_at(m.vertex_count(), static_cast<double>(h.node_count()));
    for (NodeId k = 0; k < h.node_count(); ++k) removed_at[h.node_vertex[k]] = k;
    double sum = 0.0;
    for (const Index v : salient) sum += removed_at[v];
    return sum / static_cast<double>(salient.size() * h.node_count());  // 0: first, 1: never
  };
  const double with = mean_removal(2.0), without = mean_removal(0.0);
  EXPECT_GT(with, without + 0.05) << "with saliency " << with << ", without " << without;
}

TEST(PreprocessDeterminism, SameInputSameHierarchy) {
  const TriMesh m = test::shipped_mesh("bunny_small.obj");
  PreprocessOptions one, two;
  one.threads = 1;
  two.threads = 2;
  const Hierarchy a = preprocess(m, one), b = preprocess(m, two);
  EXPECT_EQ(a.node_vertex, b.node_vertex);
  EXPECT_EQ(a.original_faces, b.original_faces);
  EXPECT_EQ(a.created_corners, b.created_corners);
  EXPECT_EQ(a.maps_bary, b.maps_bary);
}

// The file is the same byte for byte for any thread count (and however long
// the build took): caches keyed by the mesh and options stay valid.
TEST(PreprocessDeterminism, OneFileForAnyThreadCount) {
  // (The 10k sphere's rounds plan and remove hundreds of vertices on every thread.)
  for (const TriMesh& m : {test::shipped_mesh("bunny_small.obj"), test::two_spheres(3), test::capped_tube(24, 16),
                           test::icosphere(5)}) {
    std::string first;
    for (const int threads : {1, 2, 4}) {
      PreprocessOptions o;
      o.threads = threads;
      const std::string bytes = serialize_hierarchy(preprocess(m, o));
      if (first.empty()) first = bytes;
      EXPECT_TRUE(bytes == first) << threads << " threads, " << m.vertex_count() << " vertices";
    }
  }
}

}  // namespace
}  // namespace filigree
