#include "bench/soak/soak_mesh.h"

#include <cstdio>

#include "support/test_meshes.h"

namespace filigree::soak {

SoakMesh soak_mesh(int levels) {
  const TriMesh mesh = test::icosphere(levels);
  SoakMesh out;
  out.vertices = mesh.vertex_count();
  out.faces = mesh.face_count();
  char line[128];
  // %.9g: float positions survive the text round trip exactly.
  for (const Vec3& p : mesh.positions) {
    std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", p.x(), p.y(), p.z());
    out.obj += line;
  }
  for (const Triangle& f : mesh.faces) {
    std::snprintf(line, sizeof line, "f %u %u %u\n", static_cast<unsigned>(f[0] + 1), static_cast<unsigned>(f[1] + 1),
                  static_cast<unsigned>(f[2] + 1));
    out.obj += line;
  }
  return out;
}

}  // namespace filigree::soak
