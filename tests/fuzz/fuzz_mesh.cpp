// Uploads: the mesh parsers (OBJ, PLY, OFF, glTF, GLB with skins), then the
// validation every upload goes through. FILIGREE_FUZZ_FORMAT names the format
// (one executable per format, so each has its own corpus).

#include <exception>

#include "fuzz_input.h"
#include "mesh/mesh_io.h"
#include "mesh/mesh_validation.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const filigree::RiggedMesh m =
        filigree::read_rigged_mesh_from_memory(filigree::fuzz::as_string(data, size), FILIGREE_FUZZ_FORMAT);
    (void)filigree::validate_mesh(m.mesh);
  } catch (const std::exception&) {
    // A refused upload: what the server answers as INVALID_ARGUMENT.
  }
  return 0;
}
