#pragma once
// Preprocessing: a validated mesh in, a complete Hierarchy out (DESIGN §2.1).

#include <cstddef>
#include <functional>
#include <optional>

#include "hierarchy/hierarchy.h"
#include "preprocess/simplifier.h"

namespace filigree {

struct TriMesh;

struct PreprocessOptions {
  // Base size: an explicit vertex count, or a ratio of the input's vertex
  // count; neither → default_base_vertices().
  std::optional<std::size_t> base_vertices;
  std::optional<double> ratio;
  int threads = 1;
  std::function<void(double)> progress;  // fraction in [0, 1]
  // When set and true, preprocess() throws PreprocessingStopped at its next
  // check (between stages, and before every candidate removal).
  const std::atomic<bool>* stop = nullptr;
  SimplifyOptions simplify;              // target, threads and progress are set from the above
};

// 2% of the vertices, at least min(n, 100) and at most 5000: a base mesh of a
// few hundred to a few thousand vertices, which a client can pose cheaply.
std::size_t default_base_vertices(std::size_t vertex_count);

// Builds the hierarchy. Throws InvalidMeshError (mesh_validation.h) if the
// mesh is fatal or still needs repair (call repair_mesh first), and
// std::invalid_argument for a bad base size.
Hierarchy preprocess(const TriMesh& mesh, const PreprocessOptions& options);

}  // namespace filigree
