// Levels of detail: which level a budget gets, the level's mesh (a valid
// manifold of the input's topology, every vertex a vertex of the full mesh),
// and its Draco encoding on the wire.

#include <algorithm>
#include <array>
#include <cstdio>
#include <map>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "codec/delta_codec.h"
#include "codec/level_mesh_codec.h"
#include "hierarchy/detail_level.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/node_graph.h"
#include "preprocess/preprocess.h"
#include "support/test_meshes.h"

namespace filigree {
namespace {

TEST(DetailLevelVertices, RoundsDownToAPowerOfTwoBetweenBaseAndFull) {
  // A mesh of 10,000 vertices over a base of 300.
  EXPECT_EQ(detail_level_vertices(1, 300, 10000), 300u);      // below the base: the base
  EXPECT_EQ(detail_level_vertices(300, 300, 10000), 300u);
  EXPECT_EQ(detail_level_vertices(511, 300, 10000), 300u);    // 256 is below the base
  EXPECT_EQ(detail_level_vertices(512, 300, 10000), 512u);
  EXPECT_EQ(detail_level_vertices(1000, 300, 10000), 512u);
  EXPECT_EQ(detail_level_vertices(1024, 300, 10000), 1024u);
  EXPECT_EQ(detail_level_vertices(9999, 300, 10000), 8192u);
  EXPECT_EQ(detail_level_vertices(10000, 300, 10000), 10000u);  // the mesh: full detail
  EXPECT_EQ(detail_level_vertices(4000000000u, 300, 10000), 10000u);
  EXPECT_THROW(detail_level_vertices(0, 300, 10000), std::invalid_argument);
}

struct Edges {
  std::map<std::pair<Index, Index>, int> directed;  // (from, to) → faces with it
  std::set<std::pair<Index, Index>> undirected;
};

Edges edges_of(const std::vector<Triangle>& faces) {
  Edges e;
  for (const Triangle& t : faces)
    for (int k = 0; k < 3; ++k) {
      const Index a = t[k], b = t[(k + 1) % 3];
      ++e.directed[{a, b}];
      e.undirected.insert({std::min(a, b), std::max(a, b)});
    }
  return e;
}

class DetailLevelMeshTest : public ::testing::Test {
 protected:
  static const Hierarchy& hierarchy() {
    static const Hierarchy h = [] {
      PreprocessOptions o;
      o.base_vertices = 100;
      return preprocess(test::torus(40, 24), o);  // genus 1: χ = 0
    }();
    return h;
  }
};

TEST_F(DetailLevelMeshTest, EveryLevelIsAClosedOrientedManifoldOfTheInputsTopology) {
  const Hierarchy& h = hierarchy();
  const NodeGraph graph(h);
  const std::size_t base = h.base_vertices.size();
  for (std::size_t vertices : {base, std::size_t{128}, std::size_t{256}, std::size_t{512}, h.vertex_count()}) {
    const DetailLevelMesh level = detail_level_mesh(graph, vertices);
    ASSERT_EQ(level.original_ids.size(), vertices);
    EXPECT_TRUE(std::is_sorted(level.original_ids.begin(), level.original_ids.end()));
    EXPECT_EQ(std::adjacent_find(level.original_ids.begin(), level.original_ids.end()), level.original_ids.end());
    // Every base vertex is in every level.
    for (Index b : h.base_vertices)
      EXPECT_TRUE(std::binary_search(level.original_ids.begin(), level.original_ids.end(), b)) << b;
    const Edges e = edges_of(level.faces);
    // Closed and oriented: each directed edge once, and its opposite too.
    for (const auto& [edge, count] : e.directed) {
      EXPECT_EQ(count, 1) << vertices << ": edge " << edge.first << "→" << edge.second;
      EXPECT_TRUE(e.directed.contains({edge.second, edge.first})) << vertices << ": boundary edge";
    }
    const long chi = static_cast<long>(vertices) - static_cast<long>(e.undirected.size()) + static_cast<long>(level.faces.size());
    EXPECT_EQ(chi, 0) << vertices << " vertices: not a torus";
  }
}

TEST_F(DetailLevelMeshTest, LevelsNestCoarseToFine) {
  // A coarser level's vertices are all in every finer one: the levels are
  // prefixes of one recovery order.
  const Hierarchy& h = hierarchy();
  const NodeGraph graph(h);
  const DetailLevelMesh coarse = detail_level_mesh(graph, 256), fine = detail_level_mesh(graph, 512);
  EXPECT_TRUE(std::includes(fine.original_ids.begin(), fine.original_ids.end(), coarse.original_ids.begin(),
                            coarse.original_ids.end()));
  EXPECT_THROW(detail_level_mesh(graph, h.base_vertices.size() - 1), std::invalid_argument);
  EXPECT_THROW(detail_level_mesh(graph, h.vertex_count() + 1), std::invalid_argument);
}

// Faces as a set of oriented triangles: each rotated to start at its
// smallest index, then sorted (Edgebreaker reorders faces and corners).
std::vector<std::array<std::uint32_t, 3>> oriented_faces(const std::vector<std::uint32_t>& flat) {
  std::vector<std::array<std::uint32_t, 3>> out;
  for (std::size_t t = 0; t < flat.size(); t += 3) {
    std::array<std::uint32_t, 3> f{flat[t], flat[t + 1], flat[t + 2]};
    std::rotate(f.begin(), std::min_element(f.begin(), f.end()), f.end());
    out.push_back(f);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(LevelMeshCodec, RoundTripsIdsAndOrientedFaces) {
  LevelMesh mesh;
  mesh.original_ids = {3, 8, 9, 40, 41, 1000};
  mesh.faces = {0, 1, 2, 2, 1, 3, 3, 4, 5, 5, 0, 3};
  const std::string bytes = encode_level_mesh(mesh);
  const LevelMesh back = decode_level_mesh(bytes, 1001);
  EXPECT_EQ(back.original_ids, mesh.original_ids);
  EXPECT_EQ(oriented_faces(back.faces), oriented_faces(mesh.faces));
}

TEST(LevelMeshCodec, IsSmallerThanPlainIndicesOnARealLevel) {
  PreprocessOptions o;
  o.base_vertices = 100;
  const Hierarchy h = preprocess(test::icosphere(5), o);
  const NodeGraph graph(h);
  const DetailLevelMesh level = detail_level_mesh(graph, 4096);
  LevelMesh mesh;
  mesh.original_ids.assign(level.original_ids.begin(), level.original_ids.end());
  for (const Triangle& t : level.faces) mesh.faces.insert(mesh.faces.end(), t.begin(), t.end());
  const std::string bytes = encode_level_mesh(mesh);
  const LevelMesh back = decode_level_mesh(bytes, static_cast<std::uint32_t>(h.vertex_count()));
  EXPECT_EQ(back.original_ids, mesh.original_ids);
  EXPECT_EQ(oriented_faces(back.faces), oriented_faces(mesh.faces));
  // Plain 32-bit ids and indices: 4 bytes each.
  const std::size_t plain = 4 * (mesh.original_ids.size() + mesh.faces.size());
  std::printf("level of %zu vertices, %zu faces: %zu bytes (%.2f a face) against %zu plain\n", mesh.original_ids.size(),
              mesh.faces.size() / 3, bytes.size(), double(bytes.size()) / double(mesh.faces.size() / 3), plain);
  EXPECT_LT(bytes.size(), plain / 8) << bytes.size() << " bytes against " << plain;
}

TEST(LevelMeshCodec, RefusesWhatIsNoLevelMesh) {
  EXPECT_THROW(decode_level_mesh("not draco at all", 100), DeltaCodecError);
  LevelMesh beyond;
  beyond.original_ids = {1, 2, 100};
  beyond.faces = {0, 1, 2};
  EXPECT_THROW(decode_level_mesh(encode_level_mesh(beyond), 100), DeltaCodecError);  // id 100 of a 100-vertex mesh
  EXPECT_NO_THROW(decode_level_mesh(encode_level_mesh(beyond), 101));
}

}  // namespace
}  // namespace filigree
