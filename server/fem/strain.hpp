// Strain of a displacement field on a tetrahedral mesh: per tetrahedron the Green-Lagrange
// strain E = (F^T F - I) / 2 of its constant deformation gradient F = I + grad u, and the largest
// principal value in magnitude over the mesh. What the server reports as "strain" (SimStatus
// max_strain) and the accuracy benchmark tabulates the tiers' errors against.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

namespace neurosim::fem {

struct StrainSummary {
  double max_strain{0.0};  // largest |principal Green-Lagrange strain| (dimensionless; 0.1 = 10 %)
  int tet{-1};             // the tetrahedron where it is (-1: empty mesh)
  int inverted{0};         // tetrahedra with det F <= 0 (the field inverts them)
};

// u_m: 3N nodal displacements of `mesh`, unit m. Throws std::invalid_argument if the size is
// wrong or a value is not finite (naming the node).
StrainSummary max_principal_strain(const mesh::TetMesh& mesh, const Eigen::VectorXd& u_m);

}  // namespace neurosim::fem
