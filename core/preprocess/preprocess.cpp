#include "preprocess/preprocess.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "geometry/cotangent_laplacian.h"
#include "mesh/boundary_vertices.h"
#include "mesh/mesh_validation.h"
#include "preprocess/mean_curvature.h"
#include "preprocess/mesh_saliency.h"
#include "util/content_hash.h"

namespace filigree {

std::size_t default_base_vertices(std::size_t vertex_count) {
  const std::size_t two_percent = vertex_count / 50;
  return std::min(std::max(two_percent, std::min<std::size_t>(vertex_count, 100)), std::size_t{5000});
}

namespace {

std::size_t target_of(const PreprocessOptions& options, std::size_t n) {
  if (options.base_vertices && options.ratio) throw std::invalid_argument("give either a base vertex count or a ratio, not both");
  if (options.base_vertices) {
    if (*options.base_vertices < 4) throw std::invalid_argument("base vertex count must be at least 4");
    return *options.base_vertices;
  }
  if (options.ratio) {
    if (!(*options.ratio > 0.0 && *options.ratio <= 1.0)) throw std::invalid_argument("ratio must be in (0, 1]");
    return std::max<std::size_t>(4, static_cast<std::size_t>(std::llround(*options.ratio * static_cast<double>(n))));
  }
  return default_base_vertices(n);
}

}  // namespace

Hierarchy preprocess(const TriMesh& mesh, const PreprocessOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const ValidationReport report = validate_mesh(mesh);
  // repair_mesh words the precise reason for an unusable mesh; use it.
  if (report.fatal()) repair_mesh(mesh, {}, nullptr);
  if (report.fatal() || report.repairable())
    throw InvalidMeshError("mesh must be repaired before preprocessing (repair_mesh):\n" + report.to_string());
  const std::size_t target = target_of(options, mesh.vertex_count());

  Hierarchy h;
  h.mesh_hash = hash_mesh(mesh);


  const auto check_stop = [&] {
    if (options.stop && options.stop->load(std::memory_order_relaxed)) throw PreprocessingStopped();
  };
  check_stop();
  VertexTraits traits;
  traits.boundary = boundary_vertices(mesh, options.threads);
  check_stop();
  // The Laplacian (~110 B a vertex) only for the curvature, freed before
  // simplifying. The differential coordinates are not stored: the runtime
  // derives them from the rest mesh when it first optimises (DeformerModel).
  traits.curvature =
      mean_curvature(mesh, cotangent_laplacian(mesh, options.threads), std::vector<bool>(traits.boundary.begin(), traits.boundary.end()));
  check_stop();
  traits.saliency = mesh_saliency(mesh, traits.curvature, options.threads, options.stop);
  check_stop();

  SimplifyOptions so = options.simplify;
  so.target_vertices = target;
  so.threads = options.threads;
  so.progress = options.progress;
  so.stop = options.stop;
  simplify(mesh, std::move(traits), so, h);
  h.rest_positions = mesh.positions;  // after simplifying: not beside its peak

  h.build.requested_base_vertices = target;
  h.build.threads = static_cast<std::uint32_t>(std::max(options.threads, 1));
  h.build.build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  validate_hierarchy(h);
  return h;
}

}  // namespace filigree
