// Fuzz target: the TetGen .node/.ele reader (server/mesh/tetgen.cpp, text_reader.cpp) on any
// bytes, then TetMesh::build on what it accepts. The input holds both files: the .node text,
// the separator line "--- .ele ---", the .ele text (no separator: an empty .ele).
#include "fuzz/mesh_target.hpp"

#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace neurosim;
  constexpr std::string_view kSeparator = "\n--- .ele ---\n";
  const std::string_view all(reinterpret_cast<const char*>(data), size);
  const std::size_t cut = all.find(kSeparator);
  const std::string_view node = all.substr(0, cut);
  const std::string_view ele =
      cut == std::string_view::npos ? std::string_view() : all.substr(cut + kSeparator.size());
  const std::string stem = fuzz::scratch_file("input");
  fuzz::write_file(stem + ".node", node.data(), node.size());
  fuzz::write_file(stem + ".ele", ele.data(), ele.size());
  mesh::MeshData m;
  try {
    m = mesh::read_tetgen(stem + ".node");
  } catch (const std::runtime_error& e) {
    fuzz::require(std::string(e.what()).rfind(stem + ".", 0) == 0, "errors name the file");
    return 0;
  }
  fuzz::check_mesh(std::move(m));
  return 0;
}
