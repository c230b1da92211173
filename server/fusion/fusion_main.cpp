// neurosim-fusion: the new boundary S' of a host mesh around an embedded one, as .vtu files.
//
//   neurosim-fusion --figure11 [--out DIR]        paper Figure 11: cube of 195 and 1521 vertices
//   neurosim-fusion --cube-vertices N [--out DIR] one cube/cylinder pair (Figure 8c placement)
//   neurosim-fusion --brain-like [--out DIR]      brain-sized stand-in pair (fusion_bench's row)
//   neurosim-fusion --host A.mesh --embedded B.mesh [--unit-m U] [--out DIR]
// --save-meshes also writes the generated pairs as Medit files (PREFIX_host.mesh, ...).
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/fusion/paper_models.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/vtu.hpp"

#include <chrono>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

namespace {

using namespace neurosim;

int usage() {
  std::cerr << "usage:\n"
               "  neurosim-fusion --figure11 [--out DIR]\n"
               "  neurosim-fusion --cube-vertices N [--out DIR]\n"
               "  neurosim-fusion --brain-like [--out DIR]\n"
               "  (generated pairs: --save-meshes writes them as Medit .mesh too)\n"
               "  neurosim-fusion --host A.mesh --embedded B.mesh [--unit-m U] [--out DIR]\n"
               "writes PREFIX_host.vtu, PREFIX_embedded_surface.vtu, PREFIX_new_boundary.vtu\n";
  return 2;
}

void run(const mesh::TetMesh& host, const mesh::TetMesh& embedded, const std::string& prefix,
         bool save_meshes) {
  if (save_meshes) {
    mesh::write_medit(prefix + "_host.mesh", mesh::to_mesh_data(host));
    mesh::write_medit(prefix + "_embedded.mesh", mesh::to_mesh_data(embedded));
  }
  const fusion::TriangleSurface b = fusion::TriangleSurface::of(embedded, "embedded");
  const auto t0 = std::chrono::steady_clock::now();
  const fusion::NewBoundary s = fusion::find_new_boundary(host, b);
  const auto t1 = std::chrono::steady_clock::now();
  mesh::write_vtu(prefix + "_host.vtu", host);
  mesh::write_vtu(prefix + "_embedded_surface.vtu", embedded.vertices(), embedded.surface());
  mesh::write_vtu(prefix + "_new_boundary.vtu", host.vertices(), s.triangles, {},
                  {mesh::make_field("source_tet", s.source_tet)});
  std::printf("%s: host %zu vertices / %zu tets, embedded %zu vertices / %zu surface triangles\n",
              prefix.c_str(), host.num_vertices(), host.num_tets(), embedded.num_vertices(),
              embedded.surface().size());
  std::printf(
      "  S' %zu triangles, inside triangles %zu (%.1f %%), intersected faces %zu, %.3f ms\n",
      s.triangles.size(), s.stats.inside_triangles,
      100.0 * static_cast<double>(s.triangles.size()) /
          static_cast<double>(std::max<std::size_t>(1, s.stats.inside_triangles)),
      s.stats.intersected_faces, std::chrono::duration<double, std::milli>(t1 - t0).count());
  if (!s.triangles.empty()) {
    const fusion::CouplingMap m = fusion::build_coupling_map(host.vertices(), s, b);
    std::printf(
        "  B surface -> S': max %.4g m, mean %.4g m; S' -> B surface: max %.4g m, mean %.4g m\n",
        m.embedded_to_boundary.max_m, m.embedded_to_boundary.mean_m, m.boundary_to_embedded.max_m,
        m.boundary_to_embedded.mean_m);
  }
  std::printf("  wrote %s_{host,embedded_surface,new_boundary}.vtu\n", prefix.c_str());
}

}  // namespace

int main(int argc, char** argv) {
  try {
    std::string out = ".", host_path, embedded_path;
    std::vector<int> cubes;
    double unit_m = 1.0;
    bool brain_like = false, save_meshes = false;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
        return argv[++i];
      };
      if (a == "--figure11") {
        cubes.push_back(195);
        cubes.push_back(1521);
      } else if (a == "--cube-vertices") {
        cubes.push_back(std::stoi(value()));
      } else if (a == "--brain-like") {
        brain_like = true;
      } else if (a == "--save-meshes") {
        save_meshes = true;
      } else if (a == "--host") {
        host_path = value();
      } else if (a == "--embedded") {
        embedded_path = value();
      } else if (a == "--unit-m") {
        unit_m = std::stod(value());
      } else if (a == "--out") {
        out = value();
      } else {
        return usage();
      }
    }
    const int modes = (cubes.empty() ? 0 : 1) + (brain_like ? 1 : 0) +
                      (host_path.empty() && embedded_path.empty() ? 0 : 1);
    if (modes != 1) return usage();
    std::filesystem::create_directories(out);
    if (!host_path.empty()) {
      if (embedded_path.empty()) return usage();
      const mesh::TetMesh a = mesh::load_tet_mesh(host_path, unit_m);
      const mesh::TetMesh b = mesh::load_tet_mesh(embedded_path, unit_m);
      run(a, b, (std::filesystem::path(out) / "fusion").string(), false);
      return 0;
    }
    if (brain_like) {
      const fusion::MeshPair pair = fusion::make_brain_like();
      std::printf("%s\n", pair.description.c_str());
      run(pair.host, pair.embedded, (std::filesystem::path(out) / "brain_like").string(),
          save_meshes);
      return 0;
    }
    for (int n : cubes) {
      const fusion::MeshPair pair = fusion::make_cube_cylinder(n);
      std::printf("%s\n", pair.description.c_str());
      run(pair.host, pair.embedded,
          (std::filesystem::path(out) / ("figure11_cube" + std::to_string(n))).string(),
          save_meshes);
    }
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "neurosim-fusion: " << e.what() << "\n";
    return 1;
  }
}
