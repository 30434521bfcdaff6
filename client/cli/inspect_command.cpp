// `filigree inspect H.fgh`: what a hierarchy file holds; `filigree inspect
// MESH`: what an upload holds (its size and, for a skinned glTF/GLB, its
// joints and clips: what `filigree play --clip` names).

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "hierarchy/hierarchy.h"
#include "hierarchy/hierarchy_file.h"
#include "hierarchy/node_graph.h"
#include "mesh/mesh_io.h"
#include "skinning/rig.h"
#include "util/content_hash.h"

namespace filigree::cli {
namespace {

void inspect_mesh(const std::string& path) {
  const RiggedMesh m = read_rigged_mesh(path);
  std::printf("file          %s\n", path.c_str());
  std::printf("mesh          %zu vertices, %zu faces\n", m.mesh.vertex_count(), m.mesh.face_count());
  if (!m.rig) {
    std::printf("skeleton      none (not a skinned glTF/GLB): pose it by positions\n");
    return;
  }
  std::printf("skeleton      %zu joints\n", m.rig->joints.size());
  for (std::size_t j = 0; j < m.rig->joints.size(); ++j)
    std::printf("  joint %-4zu  %s (parent %d)\n", j, m.rig->joints[j].name.c_str(), m.rig->joints[j].parent);
  std::printf("clips         %zu (filigree play --clip NAME)\n", m.rig->clips.size());
  for (const AnimationClip& c : m.rig->clips) std::printf("  clip        %s, %.3f s\n", c.name.c_str(), c.duration());
}

}  // namespace

void add_inspect_command(CLI::App& app) {
  auto path = std::make_shared<std::string>();
  CLI::App* cmd = app.add_subcommand("inspect",
                                     "Print what a hierarchy file holds (and check it fully), or what a mesh file holds: "
                                     "its size and a skinned glTF/GLB's joints and animation clips");
  cmd->add_option("file", *path, "Hierarchy file (.fgh), or a mesh (.obj .ply .off .gltf .glb)")->required()->check(CLI::ExistingFile);
  cmd->callback([path] {
    if (std::filesystem::path(*path).extension() != ".fgh") return inspect_mesh(*path);
    const HierarchyFileInfo info = read_hierarchy_file_info(*path);
    const auto start = std::chrono::steady_clock::now();
    const Hierarchy h = load_hierarchy(*path);
    const double load_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    // What loading leaves to the first finite T: checked here too.
    const auto graph_start = std::chrono::steady_clock::now();
    const NodeGraph graph(h);
    const double graph_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - graph_start).count();
    std::size_t boundary_nodes = 0, max_ring = 0;
    for (NodeId k = 0; k < h.node_count(); ++k) {
      boundary_nodes += h.node_closed[k] ? 0 : 1;
      max_ring = std::max(max_ring, h.ring(k).size());
    }
    std::printf("file          %s (format v%u, %.1f MiB, loaded and validated in %.1f ms)\n", path->c_str(), info.version,
                static_cast<double>(info.file_size) / (1024.0 * 1024.0), load_ms);
    std::printf("mesh hash     %s\n", hash_to_hex(h.mesh_hash).c_str());
    std::printf("original      %zu vertices, %zu faces\n", h.vertex_count(), h.original_face_count());
    std::printf("base          %zu vertices, %zu faces\n", h.base_vertices.size(), h.base_faces.size());
    std::printf("nodes         %zu (%zu on the boundary), depth %zu, largest ring %zu\n", h.node_count(), boundary_nodes,
                h.depth(), max_ring);
    std::printf("faces stored  %zu (original + created by removals)\n", h.face_count());
    // What one more vertex costs a server (the loaded arrays) and a cache directory.
    const double n = static_cast<double>(std::max<std::size_t>(h.vertex_count(), 1));
    std::printf("size          %.1f bytes/vertex in memory (%.1f MiB), %.1f bytes/vertex on disk\n",
                static_cast<double>(h.memory_bytes()) / n, static_cast<double>(h.memory_bytes()) / (1024.0 * 1024.0),
                static_cast<double>(info.file_size) / n);
    std::printf("node graph    derived and checked in %.1f ms; %.1f bytes/vertex more once a session sets a finite T\n", graph_ms,
                static_cast<double>(graph.memory_bytes()) / n);
    std::printf("built         with a requested base of %llu vertices%s\n",
                static_cast<unsigned long long>(h.build.requested_base_vertices),
                h.base_vertices.size() > h.build.requested_base_vertices ? " (no further vertex could be removed)" : "");
  });
}

}  // namespace filigree::cli
