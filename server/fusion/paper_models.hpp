// The paper's test objects (Figure 8c, Table 2a, Table 3) and a brain-sized stand-in pair,
// generated with CGAL Mesh_3, shared by the tests, fusion_bench and neurosim-fusion.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::fusion {

struct MeshPair {
  mesh::TetMesh host;      // cube (or brain stand-in), lower priority
  mesh::TetMesh embedded;  // cylinder (or artery stand-in), higher priority
  std::string description;
};

// Placement standing in for Figure 8c: cube [0, 0.1]^3 m; cylinder of radius 0.015 m along x,
// axis through the cube's centre (y = z = 0.05 m), from x = 0.02 to 0.08 m (fully inside).
// Cylinder at the paper's Table 2a size (target 206 vertices).
struct CubeCylinderSpec {
  double cube_edge_m{0.1};
  double cylinder_radius_m{0.015};
  double cylinder_length_m{0.06};
  int cylinder_vertices{206};
  unsigned seed{1};
};

// Cube meshed near cube_vertices vertices (Table 3) with the cylinder above.
MeshPair make_cube_cylinder(int cube_vertices, const CubeCylinderSpec& spec = {});

// Paper Table 3 rows as read from the repository's bench/data/paper_table3.csv.
struct PaperRow {
  int cube_vertices{0};
  int new_boundary_triangles{0};
  int inside_triangles{0};
  double time_ms{0.0};
};
std::vector<PaperRow> read_paper_table3(const std::string& csv_path);

// Brain-sized stand-in (paper Table 2b: brain 5367 vertices / 25103 tets, artery 1644 / 4449):
// host box 0.14 x 0.11 x 0.09 m meshed near host_vertices; a long thin cylinder (radius
// 2.5 mm, 0.11 m long, oblique) near artery_vertices, fully inside.
MeshPair make_brain_like(int host_vertices = 5367, int artery_vertices = 1644, unsigned seed = 1);

}  // namespace neurosim::fusion
