#pragma once
// A mesh as a session sees it, for the runtime benchmarks: repaired and in
// the service's vertex order (a Morton curve), so their numbers are those a
// session gets.

#include <string>

#include "mesh/tri_mesh.h"

namespace filigree::bench {

TriMesh in_session_order(const TriMesh& mesh);
// Read from `path`, repaired, in session order.
TriMesh load_clean(const std::string& path);

}  // namespace filigree::bench
