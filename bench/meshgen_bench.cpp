// How close the CGAL Mesh_3 generator comes to the paper's mesh sizes (Table 2a, Table 3).
//   build/bin/meshgen_bench [--csv]
// Columns: shape, paper_vertices, vertices, vertex_error_pct, paper_tets, tets, attempts,
// cell_size_mm, min_dihedral_deg, seconds. Paper tetrahedron counts are only known for
// Table 2a (cube 1812 / 8324, cylinder 206 / 699); elsewhere they are left empty.
#include "common/cli.hpp"
#include "server/mesh/generate.hpp"
#include "server/mesh/quality.hpp"

#include <chrono>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

using neurosim::mesh::Vec3;

int main(int argc, char** argv) {
  bool csv = false;
  neurosim::cli::Parser cli("meshgen_bench", "Mesh generation of the paper's cube/cylinder pairs.");
  cli.add_flag("--csv", csv, "print CSV");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  std::vector<int> cube_sizes;
  std::ifstream table(std::string(NEUROSIM_SOURCE_DIR) + "/bench/data/paper_table3.csv");
  std::string line;
  while (std::getline(table, line)) {
    if (line.empty() || line[0] == '#' || line.rfind("cube_vertices", 0) == 0) continue;
    cube_sizes.push_back(std::stoi(line.substr(0, line.find(','))));
  }
  if (cube_sizes.empty()) {
    std::fprintf(stderr, "meshgen_bench: bench/data/paper_table3.csv not found or empty\n");
    return 1;
  }
  std::printf(csv ? "shape,paper_vertices,vertices,vertex_error_pct,paper_tets,tets,attempts,"
                    "cell_size_mm,min_dihedral_deg,seconds\n"
                  : "%-9s %8s %8s %7s %8s %8s %4s %8s %8s %7s\n",
              "shape", "paper_v", "v", "err_%", "paper_t", "t", "runs", "size_mm", "min_dih",
              "s");
  auto row = [&](const char* shape, int paper_v, int paper_t,
                 const neurosim::mesh::GeneratedMesh& g, double seconds) {
    const auto q = neurosim::mesh::quality(g.mesh);
    const double err = 100.0 * (double(g.mesh.num_vertices()) - paper_v) / paper_v;
    const std::string pt = paper_t > 0 ? std::to_string(paper_t) : "";
    std::printf(csv ? "%s,%d,%zu,%.2f,%s,%zu,%d,%.3f,%.2f,%.3f\n"
                    : "%-9s %8d %8zu %7.2f %8s %8zu %4d %8.3f %8.2f %7.3f\n",
                shape, paper_v, g.mesh.num_vertices(), err, pt.c_str(), g.mesh.num_tets(),
                g.attempts, 1e3 * g.cell_size_m, q.min_dihedral_deg, seconds);
  };
  using clock = std::chrono::steady_clock;
  for (int v : cube_sizes) {
    neurosim::mesh::MeshingOptions o;
    o.target_vertices = v;
    o.seed = 1;
    const auto t0 = clock::now();
    const auto g = neurosim::mesh::generate_box(Vec3::Zero(), Vec3::Constant(0.1), o);
    row("cube", v, v == 1812 ? 8324 : 0, g,
        std::chrono::duration<double>(clock::now() - t0).count());
  }
  neurosim::mesh::MeshingOptions o;
  o.target_vertices = 206;
  o.seed = 1;
  const auto t0 = clock::now();
  const auto g = neurosim::mesh::generate_cylinder(Vec3(0.05, 0.02, 0.05), Vec3(0, 0.06, 0), 0.015, o);
  row("cylinder", 206, 699, g, std::chrono::duration<double>(clock::now() - t0).count());
  return 0;
}
