// Pose files (`filigree deform --pose`, `drive --pose`): .pose float32 triples
// or a mesh file. The first byte picks the extension and the base size; the
// rest is the file (written once per input to a private temporary file).

#include <unistd.h>

#include <exception>
#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz_input.h"
#include "runtime/pose_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  static const char* const kExtensions[] = {".pose", ".obj", ".off", ".ply"};
  const std::string extension = kExtensions[data[0] % 4];
  const std::size_t base_vertices = data[0] / 4;  // 0…63: right or wrong for the file
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("filigree_fuzz_pose_" + std::to_string(::getpid()) + extension);
  {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(data + 1), static_cast<std::streamsize>(size - 1));
  }
  try {
    (void)filigree::read_pose(path, base_vertices);
  } catch (const std::exception&) {
  }
  return 0;
}
