// `filigree preprocess MESH -o H.fgh`: validate, repair, simplify, save.

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "cli/progress_bar.h"
#include "hierarchy/hierarchy.h"
#include "preprocess/simplifier.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "preprocess/preprocess.h"
#include "util/content_hash.h"
#include "skinning/rig_file.h"
#include "util/memory_usage.h"

namespace filigree::cli {
namespace {

struct PreprocessArgs {
  std::string mesh;
  std::string output;
  std::optional<std::size_t> base_vertices;
  std::optional<double> ratio;
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  std::optional<double> weld;
  std::string vertex_map;
};

void run(const PreprocessArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  const RiggedMesh rigged = read_rigged_mesh(a.mesh);
  const TriMesh& input = rigged.mesh;
  const ValidationReport report = validate_mesh(input);
  std::printf("input      %s: %zu vertices, %zu faces\n", a.mesh.c_str(), input.vertex_count(), input.face_count());
  if (report.components > 1 || report.boundary_loops > 0)
    std::printf("topology   %zu components, %zu boundary loops\n", report.components, report.boundary_loops);

  RepairOptions repair_options;
  if (a.weld) repair_options.weld_coincident = true, repair_options.weld_tolerance = *a.weld;
  RepairReport repair;
  const TriMesh mesh = repair_mesh(input, repair_options, &repair);
  if (repair.changed()) {
    std::printf("repaired   %s\n", repair.to_string().c_str());
    if (!a.vertex_map.empty()) {
      std::ofstream map(a.vertex_map);
      for (Index old : repair.new_to_old_vertex) map << old << '\n';
      std::printf("vertex map %s (line i: input index of hierarchy vertex i)\n", a.vertex_map.c_str());
    } else {
      std::printf("note       vertex order changed; pass --vertex-map FILE to record the mapping\n");
    }
  }

  PreprocessOptions options;
  options.base_vertices = a.base_vertices;
  options.ratio = a.ratio;
  options.threads = a.threads;
  ProgressBar bar("simplifying");
  options.progress = [&](double f) { bar.update(f); };
  SimplifyReport simplified;
  options.simplify.report = &simplified;
  const Hierarchy h = preprocess(mesh, options);
  bar.finish();
  save_hierarchy(h, a.output);
  if (rigged.rig) {
    // A skinned input keeps its rig beside the hierarchy (H.rig), in hierarchy vertex order.
    const std::filesystem::path rig_path = std::filesystem::path(a.output).replace_extension(".rig");
    save_rig(rigged.rig->restricted_to(repair.new_to_old_vertex), rig_path);
    std::printf("rig        %s: %zu joints, %zu clips (`filigree animate %s --clip NAME`)\n", rig_path.c_str(),
                rigged.rig->joints.size(), rigged.rig->clips.size(), a.output.c_str());
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  std::printf("base       %zu vertices, %zu faces (%.2f%% of the vertices)\n", h.base_vertices.size(), h.base_faces.size(),
              100.0 * static_cast<double>(h.base_vertices.size()) / static_cast<double>(h.vertex_count()));
  if (h.base_vertices.size() > h.build.requested_base_vertices) {
    // Asked for fewer than the simplification could reach: say what held the rest.
    std::string held;
    for (std::size_t r = 0; r < kBaseRefusals; ++r)
      if (simplified.refused[r] > 0)
        held += (held.empty() ? "" : ", ") + std::to_string(simplified.refused[r]) + " " + describe(static_cast<BaseRefusal>(r));
    std::printf("           not the %llu asked for: no vertex left could be removed (%s)\n",
                static_cast<unsigned long long>(h.build.requested_base_vertices), held.c_str());
  }
  std::printf("hierarchy  %zu nodes, depth %zu\n", h.node_count(), h.depth());
  std::printf("time       %.2f s total (%.2f s preprocessing, %d threads)\n", seconds, h.build.build_seconds, a.threads);
  std::printf("memory     %.1f MiB peak\n", static_cast<double>(peak_memory_bytes()) / (1024.0 * 1024.0));
  std::printf("output     %s: %.1f MiB, mesh hash %s\n", a.output.c_str(),
              static_cast<double>(std::filesystem::file_size(a.output)) / (1024.0 * 1024.0), hash_to_hex(h.mesh_hash).c_str());
}

}  // namespace

void add_preprocess_command(CLI::App& app) {
  auto args = std::make_shared<PreprocessArgs>();
  CLI::App* cmd = app.add_subcommand("preprocess", "Build the simplification hierarchy of a mesh (.obj .ply .off .gltf .glb)");
  cmd->add_option("mesh", args->mesh, "Input mesh")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", args->output, "Hierarchy file to write (.fgh)")->required();
  auto* count = cmd->add_option("--base-vertices", args->base_vertices, "Target base mesh vertex count")->check(CLI::Range(4, 1 << 30));
  auto* ratio = cmd->add_option("--ratio", args->ratio, "Target base size as a fraction of the input vertices")->check(CLI::Range(1e-9, 1.0));
  count->excludes(ratio);
  cmd->add_option("--threads", args->threads, "Worker threads")->check(CLI::Range(1, 256));
  cmd->add_option("--weld", args->weld, "Weld vertices closer than this distance before preprocessing")->check(CLI::NonNegativeNumber);
  cmd->add_option("--vertex-map", args->vertex_map, "When repair changes the vertex order, write the input index of each vertex here");
  cmd->callback([args] { run(*args); });
}

}  // namespace filigree::cli
