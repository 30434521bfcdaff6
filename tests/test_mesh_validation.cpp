// Tests for validate_mesh / repair_mesh on shipped files and small meshes built here.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"

namespace filigree {
namespace {

const std::filesystem::path kDataDir = FILIGREE_TEST_DATA_DIR;

// A closed, consistently oriented tetrahedron on vertices base..base+3.
void add_tetrahedron(TriMesh& mesh, const Vec3& offset) {
  const Index b = static_cast<Index>(mesh.positions.size());
  for (const Vec3& p : {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)}) mesh.positions.push_back(p + offset);
  for (const Triangle& f : {Triangle{0, 2, 1}, Triangle{0, 1, 3}, Triangle{0, 3, 2}, Triangle{1, 2, 3}}) {
    mesh.faces.push_back({f[0] + b, f[1] + b, f[2] + b});
  }
}

TriMesh tetrahedron() {
  TriMesh mesh;
  add_tetrahedron(mesh, Vec3::Zero());
  return mesh;
}

// An n x n grid of quads in the plane, split into triangles: one boundary loop.
TriMesh grid(int n) {
  TriMesh mesh;
  for (int j = 0; j <= n; ++j) {
    for (int i = 0; i <= n; ++i) mesh.positions.emplace_back(i, j, 0.0);
  }
  auto at = [n](int i, int j) { return static_cast<Index>(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      mesh.faces.push_back({at(i, j), at(i + 1, j), at(i + 1, j + 1)});
      mesh.faces.push_back({at(i, j), at(i + 1, j + 1), at(i, j + 1)});
    }
  }
  return mesh;
}

std::string repair_error(const TriMesh& mesh, const RepairOptions& options = {}) {
  try {
    repair_mesh(mesh, options, nullptr);
  } catch (const InvalidMeshError& e) {
    return e.what();
  }
  ADD_FAILURE() << "repair_mesh accepted the mesh";
  return {};
}

bool starts_with(const std::string& text, const std::string& prefix) { return text.rfind(prefix, 0) == 0; }

TEST(MeshValidation, BunnyIsClean) {
  const ValidationReport r = validate_mesh(read_mesh(kDataDir / "bunny_small.obj"));
  EXPECT_EQ(r.vertex_count, 1839u);
  EXPECT_EQ(r.face_count, 3674u);
  for (const IssueCount* issue :
       {&r.non_finite_vertices, &r.out_of_range_faces, &r.degenerate_faces, &r.zero_area_faces, &r.duplicate_faces,
        &r.unreferenced_vertices, &r.non_manifold_edges, &r.non_manifold_vertices, &r.inconsistent_orientation}) {
    EXPECT_EQ(issue->count, 0u);
    EXPECT_EQ(issue->first, -1);
  }
  EXPECT_EQ(r.components, 1u);
  EXPECT_EQ(r.boundary_loops, 0u);
  EXPECT_EQ(r.boundary_edges, 0u);
  EXPECT_FALSE(r.fatal());
  EXPECT_FALSE(r.repairable());
  EXPECT_EQ(r.to_string(), "vertices: 1839\nfaces: 3674\ncomponents: 1");
}

TEST(MeshValidation, OpenHeadHasThreeBoundaryLoops) {
  const TriMesh head = read_mesh(kDataDir / "head_open.off");
  const ValidationReport r = validate_mesh(head);
  EXPECT_EQ(r.boundary_loops, 3u);
  EXPECT_EQ(r.boundary_edges, 58u);
  EXPECT_EQ(r.components, 1u);
  EXPECT_FALSE(r.fatal());
  EXPECT_FALSE(r.repairable());
  // A clean mesh comes out of repair unchanged.
  RepairReport changes;
  const TriMesh repaired = repair_mesh(head, {}, &changes);
  EXPECT_FALSE(changes.changed());
  EXPECT_EQ(changes.to_string(), "no changes");
  EXPECT_EQ(repaired.positions, head.positions);
  EXPECT_EQ(repaired.faces, head.faces);
  ASSERT_EQ(changes.new_to_old_vertex.size(), head.vertex_count());
  EXPECT_EQ(changes.new_to_old_vertex[100], 100u);
  ASSERT_EQ(changes.new_to_old_face.size(), head.face_count());
}

TEST(MeshValidation, NonFiniteVertices) {
  TriMesh mesh = tetrahedron();
  add_tetrahedron(mesh, Vec3(3, 0, 0));
  mesh.positions[3].y() = std::numeric_limits<double>::quiet_NaN();
  mesh.positions[6].z() = std::numeric_limits<double>::infinity();
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.non_finite_vertices.count, 2u);
  EXPECT_EQ(r.non_finite_vertices.first, 3);
  EXPECT_TRUE(r.fatal());
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(error, "mesh is not usable: 2 vertices have NaN/Inf coordinates (first: vertex 3)\n"))
      << error;
  EXPECT_NE(error.find("non-finite vertices: 2 (first: vertex 3)"), std::string::npos) << error;
}

// Two polygons of `corners` corners glued along their rims (a flat pillow),
// each fan-triangulated from its first corner as a writer would: vertex 0
// and vertex corners − 1 are each in corners − 1 triangles (their own fan's
// corners − 2 and the other fan's last or first).
TriMesh fan_pillow(std::size_t corners) {
  TriMesh m;
  for (std::size_t i = 0; i < corners; ++i) {
    const double a = 2.0 * 3.141592653589793 * static_cast<double>(i) / static_cast<double>(corners);
    m.positions.emplace_back(std::cos(a), std::sin(a), 0.0);
  }
  const Index last = static_cast<Index>(corners - 1);
  for (Index i = 1; i + 1 < corners; ++i) m.faces.push_back({0, i, i + 1});
  for (Index i = 1; i + 1 < corners; ++i) m.faces.push_back({last, last - i, last - i - 1});
  return m;
}

TEST(MeshValidation, AVertexInTooManyFacesIsRefusedNamingTheLimit) {
  const TriMesh at_limit = fan_pillow(kMaxFacesAtVertex + 1), over = fan_pillow(kMaxFacesAtVertex + 2);
  EXPECT_EQ(validate_mesh(at_limit).crowded_vertices.count, 0u);
  const ValidationReport r = validate_mesh(over);
  EXPECT_EQ(r.crowded_vertices.count, 2u);
  EXPECT_EQ(r.crowded_vertices.first, 0);
  EXPECT_TRUE(r.fatal());
  const std::string error = repair_error(over);
  EXPECT_TRUE(starts_with(error, "mesh is not usable: 2 vertices are in more than 8192 faces")) << error;
  EXPECT_NE(error.find("triangulate it evenly"), std::string::npos) << error;
}

TEST(MeshValidation, NonFiniteUnreferencedVertexIsStillFatal) {
  TriMesh mesh = tetrahedron();
  mesh.positions.emplace_back(std::nan(""), 0, 0);
  EXPECT_TRUE(validate_mesh(mesh).fatal());
  EXPECT_TRUE(starts_with(repair_error(mesh), "mesh is not usable: 1 vertex has NaN/Inf coordinates (first: vertex 4)"));
}

TEST(MeshValidation, OutOfRangeIndices) {
  TriMesh mesh = tetrahedron();
  mesh.faces[1][2] = 99;
  mesh.faces.push_back({4, 5, 6});
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.out_of_range_faces.count, 2u);
  EXPECT_EQ(r.out_of_range_faces.first, 1);
  EXPECT_TRUE(r.fatal());
  // The bad faces are left out of the topology: the rest is an open surface.
  EXPECT_EQ(r.boundary_edges, 3u);
  EXPECT_EQ(r.boundary_loops, 1u);
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(error,
                          "mesh is not usable: 2 faces index vertices out of range (first: face 1, index 99 >= 4 vertices)"))
      << error;
}

TEST(MeshValidation, DegenerateDuplicateAndUnreferencedAreRepaired) {
  // Tetrahedron with an unreferenced vertex inserted at index 2, then a
  // degenerate face and a reversed copy of face 1.
  TriMesh mesh;
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(5, 5, 5), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  mesh.faces = {{0, 3, 1}, {0, 1, 4}, {0, 0, 3}, {0, 4, 3}, {4, 1, 0}, {1, 3, 4}};
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.degenerate_faces.count, 1u);
  EXPECT_EQ(r.degenerate_faces.first, 2);
  EXPECT_EQ(r.duplicate_faces.count, 1u);
  EXPECT_EQ(r.duplicate_faces.first, 4);
  EXPECT_EQ(r.unreferenced_vertices.count, 1u);
  EXPECT_EQ(r.unreferenced_vertices.first, 2);
  EXPECT_EQ(r.inconsistent_orientation.count, 0u);  // the duplicate takes no part in topology
  EXPECT_EQ(r.components, 1u);
  EXPECT_FALSE(r.fatal());
  EXPECT_TRUE(r.repairable());

  RepairReport changes;
  const TriMesh repaired = repair_mesh(mesh, {}, &changes);
  EXPECT_EQ(changes.removed_degenerate_faces, 1u);
  EXPECT_EQ(changes.removed_duplicate_faces, 1u);
  EXPECT_EQ(changes.removed_unreferenced_vertices, 1u);
  EXPECT_EQ(changes.welded_vertices, 0u);
  EXPECT_TRUE(changes.changed());
  EXPECT_EQ(changes.new_to_old_vertex, (std::vector<Index>{0, 1, 3, 4}));
  EXPECT_EQ(changes.new_to_old_face, (std::vector<Index>{0, 1, 3, 5}));
  EXPECT_EQ(repaired.faces, (std::vector<Triangle>{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}}));
  EXPECT_EQ(repaired.positions[2], Vec3(0, 1, 0));
  EXPECT_EQ(changes.to_string(),
            "removed degenerate faces: 1\nremoved duplicate faces: 1\nremoved unreferenced vertices: 1");
  const ValidationReport after = validate_mesh(repaired);
  EXPECT_FALSE(after.fatal());
  EXPECT_FALSE(after.repairable());
}

TEST(MeshValidation, ZeroAreaFacesAreReportedAndKept) {
  // Face 1 has distinct vertices on one line.
  TriMesh mesh;
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(2, 0, 0)};
  mesh.faces = {{0, 1, 2}, {0, 3, 1}};
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.zero_area_faces.count, 1u);
  EXPECT_EQ(r.zero_area_faces.first, 1);
  EXPECT_EQ(r.degenerate_faces.count, 0u);
  EXPECT_FALSE(r.fatal());
  EXPECT_FALSE(r.repairable());
  RepairReport changes;
  EXPECT_EQ(repair_mesh(mesh, {}, &changes).face_count(), 2u);
  EXPECT_FALSE(changes.changed());
}

TEST(MeshValidation, NonManifoldEdge) {
  // Three triangles on edge (0, 1).
  TriMesh mesh;
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1)};
  mesh.faces = {{0, 1, 2}, {1, 0, 3}, {1, 0, 4}};
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.non_manifold_edges.count, 1u);
  EXPECT_EQ(r.non_manifold_edges.first, 0);
  EXPECT_EQ(r.inconsistent_orientation.count, 0u);  // only judged on manifold edges
  EXPECT_TRUE(r.fatal());
  EXPECT_NE(r.to_string().find("non-manifold edges: 1 (first at face 0)"), std::string::npos) << r.to_string();
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(error, "mesh is not usable: non-manifold: 1 edge has more than two faces (first at face 0)\n"))
      << error;
}

TEST(MeshValidation, NonManifoldEdgeIndicesReferToInputAfterRepair) {
  TriMesh mesh;
  mesh.positions = {Vec3(9, 9, 9), Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1)};
  mesh.faces = {{1, 1, 2}, {1, 2, 3}, {2, 1, 4}, {2, 1, 5}};
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(error, "mesh is not usable: non-manifold: 1 edge has more than two faces (first at face 1)\n"))
      << error;
}

TEST(MeshValidation, BowtieVertexIsNonManifold) {
  // Two closed tetrahedra sharing only vertex 0: the second is the first's
  // template on vertices 0, 4, 5, 6.
  TriMesh mesh = tetrahedron();
  mesh.positions.insert(mesh.positions.end(), {Vec3(-1, 0, 0), Vec3(0, -1, 0), Vec3(0, 0, -1)});
  const Index remap[] = {0, 4, 5, 6};
  for (std::size_t f = 0; f < 4; ++f) {
    const Triangle t = mesh.faces[f];
    mesh.faces.push_back({remap[t[0]], remap[t[1]], remap[t[2]]});
  }
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.vertex_count, 7u);
  EXPECT_EQ(r.non_manifold_edges.count, 0u);
  EXPECT_EQ(r.non_manifold_vertices.count, 1u);
  EXPECT_EQ(r.non_manifold_vertices.first, 0);
  EXPECT_EQ(r.inconsistent_orientation.count, 0u);
  EXPECT_EQ(r.components, 1u);
  EXPECT_TRUE(r.fatal());
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(error, "mesh is not usable: non-manifold: 1 vertex joins separate surface sheets (first: vertex 0)"))
      << error;
}

TEST(MeshValidation, OpenBowtieOfTwoTriangles) {
  TriMesh mesh;
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(-1, 0, 0), Vec3(-1, -1, 0)};
  mesh.faces = {{0, 1, 2}, {0, 3, 4}};
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.non_manifold_vertices.count, 1u);
  EXPECT_EQ(r.non_manifold_vertices.first, 0);
  EXPECT_EQ(r.boundary_edges, 6u);
  EXPECT_EQ(r.boundary_loops, 2u);
}

TEST(MeshValidation, InconsistentOrientation) {
  TriMesh mesh = tetrahedron();
  std::swap(mesh.faces[2][1], mesh.faces[2][2]);
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.inconsistent_orientation.count, 3u);
  EXPECT_EQ(r.inconsistent_orientation.first, 0);
  EXPECT_EQ(r.non_manifold_edges.count, 0u);
  EXPECT_EQ(r.boundary_edges, 0u);
  EXPECT_TRUE(r.fatal());
  const std::string error = repair_error(mesh);
  EXPECT_TRUE(starts_with(
      error, "mesh is not usable: inconsistent orientation: 3 edges are used twice in the same direction (first at face 0)"))
      << error;
}

TEST(MeshValidation, TwoComponents) {
  TriMesh mesh = tetrahedron();
  add_tetrahedron(mesh, Vec3(5, 0, 0));
  const ValidationReport r = validate_mesh(mesh);
  EXPECT_EQ(r.components, 2u);
  EXPECT_FALSE(r.fatal());
  EXPECT_EQ(r.to_string(), "vertices: 8\nfaces: 8\ncomponents: 2");
}

TEST(MeshValidation, EmptyMesh) {
  const ValidationReport r = validate_mesh(TriMesh{});
  EXPECT_TRUE(r.fatal());
  EXPECT_EQ(r.components, 0u);
  const std::string error = repair_error(TriMesh{});
  EXPECT_TRUE(starts_with(error, "mesh is not usable: empty (0 vertices, 0 faces)")) << error;

  TriMesh points;
  points.positions = {Vec3(0, 0, 0)};
  EXPECT_TRUE(validate_mesh(points).fatal());
  EXPECT_TRUE(starts_with(repair_error(points), "mesh is not usable: empty (1 vertex, 0 faces)"));

  // Faces exist but none is usable.
  TriMesh degenerate = tetrahedron();
  degenerate.faces = {{0, 1, 1}, {2, 2, 2}};
  EXPECT_TRUE(validate_mesh(degenerate).fatal());
  EXPECT_TRUE(starts_with(repair_error(degenerate), "mesh is not usable: no usable faces"));
}

TEST(MeshValidation, WeldsCoincidentCopies) {
  // Two triangles of a square, the second using its own copies (3 and 4) of
  // the shared corners 0 and 2; -0.0 equals 0.0.
  TriMesh mesh;
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0), Vec3(-0.0, 0, 0), Vec3(1, 1, 0), Vec3(0, 1, 0)};
  mesh.faces = {{0, 1, 2}, {3, 4, 5}};
  const ValidationReport before = validate_mesh(mesh);
  EXPECT_EQ(before.components, 2u);
  EXPECT_EQ(before.boundary_loops, 2u);

  RepairReport changes;
  const TriMesh welded = repair_mesh(mesh, {.weld_coincident = true, .weld_tolerance = 0.0}, &changes);
  EXPECT_EQ(changes.welded_vertices, 2u);
  EXPECT_EQ(changes.removed_unreferenced_vertices, 0u);
  EXPECT_EQ(welded.vertex_count(), 4u);
  EXPECT_EQ(changes.new_to_old_vertex, (std::vector<Index>{0, 1, 2, 5}));
  EXPECT_EQ(changes.new_to_old_face, (std::vector<Index>{0, 1}));
  EXPECT_EQ(welded.faces, (std::vector<Triangle>{{0, 1, 2}, {0, 2, 3}}));
  const ValidationReport after = validate_mesh(welded);
  EXPECT_EQ(after.components, 1u);
  EXPECT_EQ(after.boundary_edges, 4u);
  EXPECT_EQ(after.boundary_loops, 1u);
  EXPECT_NE(changes.to_string().find("welded vertices: 2"), std::string::npos);

  // Slightly off: exact welding joins only the corner 0 copy, which leaves a
  // bowtie; a tolerance joins both, keeping the lowest index's position.
  mesh.positions[4] = Vec3(1, 1 + 1e-9, 0);
  EXPECT_NE(repair_error(mesh, {.weld_coincident = true, .weld_tolerance = 0.0}).find("non-manifold"),
            std::string::npos);
  const TriMesh tolerant = repair_mesh(mesh, {.weld_coincident = true, .weld_tolerance = 1e-6}, &changes);
  EXPECT_EQ(changes.welded_vertices, 2u);
  EXPECT_EQ(tolerant.faces, welded.faces);
  EXPECT_EQ(tolerant.positions[2], Vec3(1, 1, 0));
}

TEST(MeshValidation, WeldingDropsFacesItCollapses) {
  TriMesh mesh = grid(1);
  mesh.positions.push_back(Vec3(5, 5, 0));
  mesh.positions.push_back(Vec3(5, 5 + 1e-9, 0));
  mesh.positions.push_back(Vec3(6, 5, 0));
  mesh.faces.push_back({4, 5, 6});  // collapses when 5 merges into 4
  RepairReport changes;
  const TriMesh welded = repair_mesh(mesh, {.weld_coincident = true, .weld_tolerance = 1e-6}, &changes);
  EXPECT_EQ(changes.welded_vertices, 1u);
  EXPECT_EQ(changes.removed_degenerate_faces, 1u);
  EXPECT_EQ(changes.removed_unreferenced_vertices, 2u);  // 4 and 6 lose their only face
  EXPECT_EQ(welded.vertex_count(), 4u);
  EXPECT_EQ(welded.face_count(), 2u);
}

TEST(MeshValidation, RejectsBadWeldTolerance) {
  EXPECT_THROW(repair_mesh(tetrahedron(), {.weld_coincident = true, .weld_tolerance = -1.0}, nullptr),
               std::invalid_argument);
}

// Scale check; the time is printed rather than asserted (sanitizer builds are slow).
TEST(MeshValidation, MillionVertexGrid) {
  const int n = 999;  // 1,000,000 vertices, ~2M faces
  const TriMesh mesh = grid(n);
  const auto start = std::chrono::steady_clock::now();
  const ValidationReport r = validate_mesh(mesh);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("validate_mesh on %zu vertices, %zu faces: %.3f s\n", mesh.vertex_count(), mesh.face_count(), seconds);
  EXPECT_EQ(r.vertex_count, 1000000u);
  EXPECT_EQ(r.components, 1u);
  EXPECT_EQ(r.boundary_loops, 1u);
  EXPECT_EQ(r.boundary_edges, 4u * n);
  EXPECT_FALSE(r.fatal());
  EXPECT_FALSE(r.repairable());
}

}  // namespace
}  // namespace filigree
