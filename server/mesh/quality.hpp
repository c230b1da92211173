// Element quality of a tetrahedral mesh: dihedral angles, radius-edge ratio, bad elements.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::mesh {

struct QualityReport {
  // Over the tetrahedra with non-zero volume (degenerate ones are only counted).
  double min_dihedral_deg{0.0};        // unit degree; a regular tetrahedron has 70.53
  double max_dihedral_deg{0.0};        // unit degree
  double max_radius_edge_ratio{0.0};   // circumradius / shortest edge; regular: sqrt(6)/4
  double mean_radius_edge_ratio{0.0};  // same, averaged
  int inverted{0};     // negative signed volume (beyond the zero-volume threshold)
  int zero_volume{0};  // |volume| <= degenerate_volume_ratio * (mean edge length)^3
  int num_tets{0};
  int num_vertices{0};

  // One line: "12 vertices, 40 tets, dihedral [35.2, 130.1] deg, radius-edge max 1.2 mean 0.8,
  // inverted 0, zero-volume 0".
  std::string summary() const;
};

// From raw arrays, so input can be judged before TetMesh::build fixes or refuses it.
// Throws std::invalid_argument on a non-finite coordinate or an index out of range.
QualityReport quality(const std::vector<Vec3>& vertices_m, const std::vector<Tet>& tets,
                      double degenerate_volume_ratio = 1e-12);
QualityReport quality(const TetMesh& mesh, double degenerate_volume_ratio = 1e-12);

// Per-tetrahedron measures (for colouring a mesh by quality or finding the worst elements).
struct TetQuality {
  double volume_m3;          // signed, unit m^3
  double min_dihedral_deg;   // unit degree
  double max_dihedral_deg;   // unit degree
  double radius_edge_ratio;  // circumradius / shortest edge (inf when the volume is zero)
};
TetQuality tet_quality(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d);

}  // namespace neurosim::mesh
