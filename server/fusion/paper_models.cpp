#include "server/fusion/paper_models.hpp"

#include "server/mesh/generate.hpp"

#include <fstream>
#include <sstream>
#include <stdexcept>

namespace neurosim::fusion {

using mesh::Vec3;

MeshPair make_cube_cylinder(int cube_vertices, const CubeCylinderSpec& spec) {
  mesh::MeshingOptions cube_opt;
  cube_opt.target_vertices = cube_vertices;
  cube_opt.seed = spec.seed;
  const double e = spec.cube_edge_m;
  mesh::GeneratedMesh cube = mesh::generate_box(Vec3::Zero(), Vec3(e, e, e), cube_opt);

  mesh::MeshingOptions cyl_opt;
  cyl_opt.target_vertices = spec.cylinder_vertices;
  cyl_opt.seed = spec.seed;
  const Vec3 base(0.5 * (e - spec.cylinder_length_m), 0.5 * e, 0.5 * e);
  mesh::GeneratedMesh cyl = mesh::generate_cylinder(base, Vec3(spec.cylinder_length_m, 0, 0),
                                                    spec.cylinder_radius_m, cyl_opt);
  std::ostringstream d;
  d << "cube " << e << " m (" << cube.mesh.num_vertices() << " vertices, " << cube.mesh.num_tets()
    << " tets), cylinder r " << spec.cylinder_radius_m << " m x " << spec.cylinder_length_m
    << " m along x through the centre (" << cyl.mesh.num_vertices() << " vertices, "
    << cyl.mesh.num_tets() << " tets)";
  return {std::move(cube.mesh), std::move(cyl.mesh), d.str()};
}

std::vector<PaperRow> read_paper_table3(const std::string& csv_path) {
  std::ifstream in(csv_path);
  if (!in) throw std::runtime_error("cannot read " + csv_path);
  std::vector<PaperRow> rows;
  std::string line;
  int line_no = 0;
  bool header_seen = false;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    if (!header_seen) {
      if (line.rfind("cube_vertices,new_boundary_triangles,inside_triangles,time_ms", 0) != 0) {
        throw std::runtime_error(csv_path + ":" + std::to_string(line_no) +
                                 ": unexpected header '" + line + "'");
      }
      header_seen = true;
      continue;
    }
    std::istringstream s(line);
    PaperRow r;
    char c1 = 0, c2 = 0, c3 = 0;
    if (!(s >> r.cube_vertices >> c1 >> r.new_boundary_triangles >> c2 >> r.inside_triangles >>
          c3 >> r.time_ms) ||
        c1 != ',' || c2 != ',' || c3 != ',' || r.cube_vertices <= 0 || !(r.time_ms > 0.0)) {
      throw std::runtime_error(csv_path + ":" + std::to_string(line_no) + ": bad row '" + line +
                               "'");
    }
    rows.push_back(r);
  }
  if (rows.empty()) throw std::runtime_error(csv_path + ": no rows");
  return rows;
}

MeshPair make_brain_like(int host_vertices, int artery_vertices, unsigned seed) {
  mesh::MeshingOptions host_opt;
  host_opt.target_vertices = host_vertices;
  host_opt.seed = seed;
  const Vec3 lo(0, 0, 0), hi(0.14, 0.11, 0.09);
  mesh::GeneratedMesh host = mesh::generate_box(lo, hi, host_opt);

  mesh::MeshingOptions art_opt;
  art_opt.target_vertices = artery_vertices;
  art_opt.seed = seed;
  // Oblique thin tube through the middle, both ends inside the box.
  const Vec3 a(0.025, 0.03, 0.03), b(0.12, 0.08, 0.06);
  mesh::GeneratedMesh art = mesh::generate_cylinder(a, b - a, 0.0025, art_opt);
  std::ostringstream d;
  d << "box 0.14 x 0.11 x 0.09 m (" << host.mesh.num_vertices() << " vertices, "
    << host.mesh.num_tets()
    << " tets), tube r 2.5 mm from (0.025,0.03,0.03) to (0.12,0.08,0.06) m ("
    << art.mesh.num_vertices() << " vertices, " << art.mesh.num_tets() << " tets)";
  return {std::move(host.mesh), std::move(art.mesh), d.str()};
}

}  // namespace neurosim::fusion
