#include "cli/rest_mesh.h"

namespace filigree::cli {

TriMesh rest_mesh(const SessionMesh& session) {
  TriMesh mesh;
  mesh.positions = points_from_xyz(session.rest_positions);
  mesh.faces.resize(session.rest_faces.size() / 3);
  for (std::size_t f = 0; f < mesh.faces.size(); ++f)
    mesh.faces[f] = {session.rest_faces[3 * f], session.rest_faces[3 * f + 1], session.rest_faces[3 * f + 2]};
  return mesh;
}

}  // namespace filigree::cli
