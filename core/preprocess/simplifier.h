#pragma once
// Simplification by vertex removal, building the dependency hierarchy, the
// MAPS parameterisation and each node's ring coordinates as it goes
// (thesis §3.1.1–3.1.2, DESIGN §2.1 steps 1–5).

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <stdexcept>
#include <vector>

#include "mesh/tri_mesh.h"

namespace filigree {

struct Hierarchy;

// Why a vertex cannot be removed (the first check its removal fails).
enum class BaseRefusal : std::uint8_t {
  kTopology,  // the mesh would stop being a manifold of the same topology (a new edge exists, a valence too low)
  kValence,   // its ring has more than 32 vertices
  kBoundary,  // a boundary corner, or the last gap of a boundary loop
  kShape,     // the hole's triangles would be worse than min_triangle_quality (or than those they replace)
  kNormal,    // a new triangle would turn more than max_normal_change_deg from the fan
};
inline constexpr std::size_t kBaseRefusals = 5;
const char* describe(BaseRefusal why);

// What stopped a simplification above its target: how many of the vertices
// left fail each check (all zero when the target was reached).
struct SimplifyReport {
  std::array<std::size_t, kBaseRefusals> refused{};
};

struct SimplifyOptions {
  // Stop when this many vertices remain, or earlier when no removal is valid.
  std::size_t target_vertices = 0;
  // New triangles must reach this shape quality (triangle_quality), or at
  // least the worst quality of the triangles they replace on poor meshes.
  double min_triangle_quality = 0.15;
  // Largest angle between a new triangle's normal and the removed fan's normal.
  double max_normal_change_deg = 45.0;
  // A boundary vertex may be removed only where the boundary turns by less
  // than this, so boundary loops keep their shape and count.
  double max_boundary_turn_deg = 20.0;
  // Cost = (error + size_weight·spoke length) · (1 + saliency_weight·S) / (1 + curvature_weight·C).
  double size_weight = 0.05;
  double saliency_weight = 2.0;
  double curvature_weight = 1.0;
  int threads = 1;
  // Filled when the simplification stops above its target (may be null;
  // must outlive the call).
  SimplifyReport* report = nullptr;
  // Called with the fraction done in [0, 1], at most ~200 times.
  std::function<void(double)> progress;
  // When set and true, the simplification stops with PreprocessingStopped
  // (checked before every candidate removal: a server shutting down does not
  // wait for a pathological mesh). Must outlive the call.
  const std::atomic<bool>* stop = nullptr;
};

// Preprocessing was stopped through SimplifyOptions::stop (PreprocessOptions::stop).
struct PreprocessingStopped : std::runtime_error {
  PreprocessingStopped() : std::runtime_error("preprocessing was stopped") {}
};

// Per-vertex inputs of the simplification's cost and checks.
struct VertexTraits {
  std::vector<double> curvature;       // mean curvature (mean_curvature.h)
  std::vector<double> saliency;        // mesh_saliency.h
  std::vector<std::uint8_t> boundary;  // boundary_vertices.h
};

// Simplifies `mesh` and fills `out`'s faces, nodes, base mesh and MAPS
// parameterisation (everything but mesh_hash and build). The result depends
// on the mesh and the options only, not on options.threads.
// Precondition: mesh is edge- and vertex-manifold, consistently oriented,
// without degenerate/duplicate faces or unreferenced vertices
// (validate_mesh reports nothing fatal or repairable); `traits` has one
// entry per vertex in each array.
// `traits` is taken (and freed early): pass it with std::move.
void simplify(const TriMesh& mesh, VertexTraits traits, const SimplifyOptions& options, Hierarchy& out);

}  // namespace filigree
