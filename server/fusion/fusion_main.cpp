// neurosim-fusion: the new boundary S' of a host mesh around an embedded one, as .vtu files.
//
//   neurosim-fusion --figure11 [--out DIR]        paper Figure 11: cube of 195 and 1521 vertices
//   neurosim-fusion --cube-vertices N [--out DIR] one cube/cylinder pair (Figure 8c placement)
//   neurosim-fusion --brain-like [--out DIR]      brain-sized stand-in pair (fusion_bench's row)
//   neurosim-fusion --host A.mesh --embedded B.mesh [--unit-m U] [--out DIR]
// --save-meshes also writes the generated pairs as Medit files (PREFIX_host.mesh, ...).
// --help lists the options; usage errors exit 2.
#include "common/cli.hpp"
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
namespace cli = neurosim::cli;

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
  std::string out = ".", host_path, embedded_path;
  std::vector<int> cube_vertices;
  double unit_m = 1.0;
  bool figure11 = false, brain_like = false, save_meshes = false;
  cli::Parser p("neurosim-fusion",
                "The new boundary S' of a host mesh around an embedded one: writes "
                "PREFIX_host.vtu, PREFIX_embedded_surface.vtu, PREFIX_new_boundary.vtu.");
  p.add_flag("--figure11", figure11, "paper Figure 11: cubes of 195 and 1521 vertices");
  p.add_option("--cube-vertices", cube_vertices,
               "one cube/cylinder pair of N cube vertices (Figure 8c placement; repeatable)")
      ->take_all();
  p.add_flag("--brain-like", brain_like, "brain-sized stand-in pair (fusion_bench's row)");
  p.add_flag("--save-meshes", save_meshes,
             "generated pairs: also write them as Medit .mesh (PREFIX_host.mesh, ...)");
  p.add_option("--host", host_path, "host mesh file");
  p.add_option("--embedded", embedded_path, "embedded mesh file");
  p.add_option("--unit-m", unit_m, "mesh file unit, in m")
      ->check(cli::positive())
      ->capture_default_str();
  p.add_option("--out", out, "output folder")->capture_default_str();
  if (auto rc = p.parse(argc, argv)) return *rc;
  std::vector<int> cubes;
  if (figure11) cubes = {195, 1521};
  cubes.insert(cubes.end(), cube_vertices.begin(), cube_vertices.end());
  const int modes = (cubes.empty() ? 0 : 1) + (brain_like ? 1 : 0) +
                    (host_path.empty() && embedded_path.empty() ? 0 : 1);
  if (modes != 1)
    return p.usage_error(
        "give one of --figure11 / --cube-vertices N, --brain-like, --host A.mesh --embedded "
        "B.mesh");
  if (!host_path.empty() && embedded_path.empty())
    return p.usage_error("--host needs --embedded");
  if (host_path.empty() && !embedded_path.empty())
    return p.usage_error("--embedded needs --host");
  try {
    std::filesystem::create_directories(out);
    if (!host_path.empty()) {
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
