#pragma once
// The soak's mesh, made in code so the run needs no data files.

#include <cstddef>
#include <string>

namespace filigree::soak {

struct SoakMesh {
  std::string obj;  // the upload, OBJ text
  std::size_t vertices = 0, faces = 0;
};

// A unit icosphere subdivided `levels` times (levels 5: 10242 vertices),
// written as OBJ.
SoakMesh soak_mesh(int levels);

}  // namespace filigree::soak
