#pragma once
// A joined session's rest mesh as a TriMesh, for the commands that write
// meshes (watch -o, export-history).

#include "filigree/client.h"
#include "mesh/tri_mesh.h"

namespace filigree::cli {

TriMesh rest_mesh(const SessionMesh& session);

}  // namespace filigree::cli
