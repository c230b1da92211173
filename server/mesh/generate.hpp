// Tetrahedral meshes of simple solids (the paper's cube and cylinder, Table 2a and Table 3),
// made by a real mesher: CGAL Mesh_3 on a polyhedral domain with protected sharp edges.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <cstdint>

namespace neurosim::mesh {

struct MeshingOptions {
  // Aim for this many vertices: the cell size is searched for it (bisection on size).
  // 0: use cell_size_m as given.
  int target_vertices{0};
  double cell_size_m{0.0};  // unit m; used when target_vertices == 0
  // Radius-edge bound of CGAL's refinement (lower: better shaped, more vertices).
  double cell_radius_edge_ratio{2.0};
  // Sliver removal on the final mesh (the cell-size search counts vertices without it; neither
  // step adds or removes vertices): CGAL's perturbation (moves vertices until every dihedral
  // angle exceeds perturb_sliver_bound_deg or none improves), then exudation (weights).
  bool perturb_slivers{true};
  double perturb_sliver_bound_deg{12.0};
  bool exude_slivers{true};
  std::uint32_t seed{0};  // CGAL's random generator seed: same seed, same mesh
  // Facet sample count for the cylinder's polygonal approximation (per circle).
  int circle_segments{0};  // 0: chosen from the cell size
};

struct GeneratedMesh {
  TetMesh mesh;
  double cell_size_m{0.0};  // the size that produced it
  int attempts{0};          // mesher runs needed to approach target_vertices
};

// Axis-aligned box [lo, hi] (m).
GeneratedMesh generate_box(const Vec3& lo_m, const Vec3& hi_m, const MeshingOptions& options);

// Solid circular cylinder: base centre, axis vector (length = height), radius (m).
GeneratedMesh generate_cylinder(const Vec3& base_center_m, const Vec3& axis_m, double radius_m,
                                const MeshingOptions& options);

}  // namespace neurosim::mesh
