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
  // A request whose expected size (expected_tetrahedra) is above this is refused before the
  // mesher runs: an absurd cell size or box must not run for hours or exhaust memory. About a
  // hundred times the patient model; unit tetrahedra.
  double max_tetrahedra{2e6};
  // Wall-clock limit of each sliver step (perturbation, then exudation), unit s; 0: none. The
  // bundled scenes need well under a second per step, so their meshes stay reproducible (a limit
  // that binds makes the mesh depend on the machine's load); a huge mesh stops here instead of
  // running for hours, and GeneratedMesh says so.
  double optimization_time_limit_s{60.0};
};

struct GeneratedMesh {
  TetMesh mesh;
  double cell_size_m{0.0};  // the size that produced it
  int attempts{0};          // mesher runs needed to approach target_vertices
  bool optimization_time_limited{false};  // a sliver step stopped at optimization_time_limit_s
};

// Tetrahedra per vertex of Mesh_3 at radius-edge 2: 4 (small meshes) to 6; the estimates use 6.
inline constexpr double kTetsPerVertex = 6.0;

// Expected number of tetrahedra of a solid whose bounding box has these extents (m) meshed
// with `options` (target_vertices, else cell_size_m): 6 per vertex, or 10 per cell of a grid of
// the cell size over the box. Both are overestimates of what Mesh_3 makes (4 to 6 tetrahedra
// per vertex). What max_tetrahedra is compared with before meshing.
double expected_tetrahedra(const Vec3& extent_m, const MeshingOptions& options);

// Peak memory of loading a scene mesh with this many vertices and building the interactive
// simulation on it (neurosim-server: the mesh, its stiffness factor, compliance columns, the
// inclusion decision), unit byte. Measured on the generated cube of scenes/cube_cylinder.scene
// (neurosim-server peak RSS: 314 MB at 9,905 vertices, 629 MB at 20,061: 31.4 kB per vertex,
// bench/RESULTS.md "Load memory"), with a margin of 1.5 for the factor's fill growing faster
// than linearly on larger meshes. What a scene's mesh is checked against before it is generated
// or built (scene::load_mesh), so a mesh too large for the machine is refused with this
// estimate instead of ending in std::bad_alloc after minutes.
inline constexpr double kLoadBytesPerVertex = 1.5 * 31.4e3;
inline double expected_load_bytes(double vertices) { return kLoadBytesPerVertex * vertices; }

// Both throw std::invalid_argument naming the option (target_vertices, cell_size_m) when the
// expected size is above options.max_tetrahedra, before meshing.

// Axis-aligned box [lo, hi] (m).
GeneratedMesh generate_box(const Vec3& lo_m, const Vec3& hi_m, const MeshingOptions& options);

// Solid circular cylinder: base centre, axis vector (length = height), radius (m).
GeneratedMesh generate_cylinder(const Vec3& base_center_m, const Vec3& axis_m, double radius_m,
                                const MeshingOptions& options);

}  // namespace neurosim::mesh
