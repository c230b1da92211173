// Fuzz target: the Gmsh .msh reader (2.x, 4.0, 4.1 ASCII; server/mesh/gmsh.cpp,
// text_reader.cpp) on any bytes, then TetMesh::build on what it accepts. A reader may only throw
// std::runtime_error naming the file and line (or std::invalid_argument from the build).
#include "fuzz/mesh_target.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace neurosim;
  const std::string path = fuzz::scratch_file("input.msh");
  fuzz::write_file(path, data, size);
  mesh::MeshData m;
  try {
    m = mesh::read_gmsh(path);
  } catch (const std::runtime_error& e) {
    fuzz::require(std::string(e.what()).rfind(path + ":", 0) == 0, "errors name the file");
    return 0;
  }
  fuzz::check_mesh(std::move(m));
  return 0;
}
