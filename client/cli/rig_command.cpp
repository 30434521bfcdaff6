// `filigree rig MESH -o RIGGED.glb`: a skinned glTF made from any mesh with
// the automatic chain rig (core/skinning/auto_rig.h), for trying skeletal
// poses and clips on meshes that come without a skeleton.

#include <cstdio>
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "mesh/gltf_io.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "skinning/auto_rig.h"

namespace filigree::cli {
namespace {

struct RigArgs {
  std::string mesh, output;
  AutoRigOptions options;
};

void rig(const RigArgs& a) {
  // Repaired first, so the file uploads as it is (no vertex the server would drop).
  const TriMesh mesh = repair_mesh(read_mesh(a.mesh), {}, nullptr);
  const Rig r = auto_rig(mesh, a.options);
  write_glb_rigged(mesh, r, a.output);
  std::printf("%s: %zu vertices, %zu joints along the longest axis, clips:", a.output.c_str(), mesh.vertex_count(),
              r.joints.size());
  for (const AnimationClip& c : r.clips) std::printf(" %s (%.2f s)", c.name.c_str(), c.duration());
  std::printf("\n");
}

}  // namespace

void add_rig_command(CLI::App& app) {
  auto a = std::make_shared<RigArgs>();
  CLI::App* cmd = app.add_subcommand("rig", "Make a skinned .glb from a mesh: a chain of joints along its longest axis, with bend and twist clips");
  cmd->add_option("mesh", a->mesh, "Mesh file (.obj .ply .off .gltf .glb)")->required()->check(CLI::ExistingFile);
  cmd->add_option("-o,--output", a->output, "Skinned mesh to write (.glb)")->required();
  cmd->add_option("--joints", a->options.joints, "Joints in the chain")->check(CLI::Range(2, 64));
  cmd->add_option("--bend", a->options.bend_degrees, "Total bend of the clips, degrees")->check(CLI::Range(0.0, 360.0));
  cmd->add_option("--seconds", a->options.clip_seconds, "Duration of each clip")->check(CLI::PositiveNumber);
  cmd->callback([a] { rig(*a); });
}

}  // namespace filigree::cli
