// Mesh file dispatch by extension, and loading straight into a TetMesh.
#include "server/mesh/io.hpp"
#include "server/mesh/text_reader.hpp"

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <stdexcept>

namespace neurosim::mesh {

MeshData read_mesh(const std::string& path, double unit_m) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".mesh") return read_medit(path, unit_m);
  if (ext == ".msh") return read_gmsh(path, unit_m);
  if (ext == ".node" || ext == ".ele") return read_tetgen(path, unit_m);
  throw std::runtime_error(path + ": unknown mesh format '" + ext +
                           "' (expected .mesh, .msh, .node or .ele)");
}

TetMesh load_tet_mesh(const std::string& path, double unit_m, BuildOptions options) {
  MeshData data = read_mesh(path, unit_m);
  if (options.source == BuildOptions{}.source) options.source = path;
  std::vector<int> labels = std::move(data.tet_labels);
  return guard_out_of_memory(path, [&] {
    TetMesh mesh = TetMesh::build(std::move(data.vertices_m), std::move(data.tets), options);
    if (!labels.empty()) mesh.set_tet_labels(std::move(labels));
    return mesh;
  });
}

MeshData to_mesh_data(const TetMesh& mesh) {
  MeshData d;
  d.vertices_m = mesh.vertices();
  d.tets = mesh.tets();
  d.tet_labels = mesh.tet_labels();
  d.triangles = mesh.surface();
  d.triangle_labels.assign(d.triangles.size(), 0);
  d.source = mesh.source();
  return d;
}

}  // namespace neurosim::mesh
