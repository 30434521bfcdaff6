// `filigree compare A B`: prints compare_meshes(A, B) as one JSON object, so a
// script or the benchmark can collect the quality numbers of DESIGN §2.3.

#include "cli/commands.h"

#include <cstdio>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "mesh/mesh_io.h"
#include "metrics/mesh_metrics.h"

namespace filigree::cli {
namespace {

struct CompareArgs {
  std::string result, reference;
};

void compare(const CompareArgs& a) {
  const MeshComparison c = compare_meshes(read_mesh(a.result), read_mesh(a.reference));
  std::printf("%s\n", to_json(c).c_str());
}

}  // namespace

void add_compare_command(CLI::App& app) {
  auto args = std::make_shared<CompareArgs>();
  CLI::App* c = app.add_subcommand(
      "compare", "Compare mesh A with reference mesh B vertex by vertex (distance, normals, curvature) and print JSON");
  c->add_option("result", args->result, "Mesh to measure (any readable format)")->required()->check(CLI::ExistingFile);
  c->add_option("reference", args->reference, "Reference mesh with the same vertices and faces")
      ->required()
      ->check(CLI::ExistingFile);
  c->callback([args] { compare(*args); });
}

}  // namespace filigree::cli
