// `filigree export-base` and `filigree export-cut`: meshes out of a hierarchy.

#include <cstdio>
#include <fstream>
#include <stdexcept>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "hierarchy/cut_state.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "mesh/mesh_io.h"

namespace filigree::cli {
namespace {

struct ExportBaseArgs {
  std::string hierarchy, output, ids;
};

struct ExportCutArgs {
  std::string hierarchy, output, recover;
};

void export_base(const ExportBaseArgs& a) {
  const Hierarchy h = load_hierarchy(a.hierarchy);
  const TriMesh base = h.base_mesh();
  write_mesh(base, a.output);
  std::printf("wrote %s: base mesh, %zu vertices, %zu faces\n", a.output.c_str(), base.vertex_count(), base.face_count());
  if (!a.ids.empty()) {
    std::ofstream ids(a.ids);
    for (Index v : h.base_vertices) ids << v << '\n';
    if (!ids.flush()) throw std::runtime_error(a.ids + ": write failed");
    std::printf("wrote %s: original vertex id of each base vertex\n", a.ids.c_str());
  }
}

void export_cut(const ExportCutArgs& a) {
  const Hierarchy h = load_hierarchy(a.hierarchy);
  std::size_t count = h.node_count();
  if (a.recover != "all") {
    std::size_t used = 0;
    unsigned long long k = 0;
    try {
      k = std::stoull(a.recover, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != a.recover.size() || a.recover.empty() || a.recover[0] == '-')
      throw std::invalid_argument("--recover takes a node count or 'all', not '" + a.recover + "'");
    if (k > h.node_count())
      throw std::invalid_argument("--recover " + a.recover + ": the hierarchy has only " + std::to_string(h.node_count()) + " nodes");
    count = k;
  }
  const NodeGraph graph(h);
  CutState cut(graph);
  const std::vector<NodeId> order = recovery_order(h);
  for (std::size_t i = 0; i < count; ++i) cut.recover(order[i]);
  const TriMesh mesh = cut.mesh();
  write_mesh(mesh, a.output);
  std::printf("wrote %s: cut with %zu of %zu nodes recovered, %zu vertices, %zu faces\n", a.output.c_str(), count,
              h.node_count(), mesh.vertex_count(), mesh.face_count());
}

}  // namespace

void add_export_commands(CLI::App& app) {
  auto base = std::make_shared<ExportBaseArgs>();
  CLI::App* b = app.add_subcommand("export-base", "Write the base mesh in base order (.obj .ply .glb)");
  b->add_option("hierarchy", base->hierarchy, "Hierarchy file (.fgh)")->required()->check(CLI::ExistingFile);
  b->add_option("-o,--output", base->output, "Mesh file to write")->required();
  b->add_option("--ids", base->ids, "Also write the original vertex id of each base vertex, one per line");
  b->callback([base] { export_base(*base); });

  auto cut = std::make_shared<ExportCutArgs>();
  CLI::App* c = app.add_subcommand("export-cut", "Write the mesh after recovering K nodes in a valid order (all: the original)");
  c->add_option("hierarchy", cut->hierarchy, "Hierarchy file (.fgh)")->required()->check(CLI::ExistingFile);
  c->add_option("--recover", cut->recover, "Number of nodes to recover, or 'all'")->required();
  c->add_option("-o,--output", cut->output, "Mesh file to write")->required();
  c->callback([cut] { export_cut(*cut); });
}

}  // namespace filigree::cli
