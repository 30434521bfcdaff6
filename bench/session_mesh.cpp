#include "bench/session_mesh.h"

#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"
#include "mesh/vertex_order.h"

namespace filigree::bench {

TriMesh in_session_order(const TriMesh& mesh) { return permute_vertices(mesh, locality_order(mesh.positions)); }

TriMesh load_clean(const std::string& path) {
  RepairReport report;
  return in_session_order(repair_mesh(read_mesh(path), {}, &report));
}

}  // namespace filigree::bench
