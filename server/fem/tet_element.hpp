// Constant-strain (linear, 4-node) tetrahedron: geometry, stiffness, strain energy, quality.
#pragma once

#include "server/fem/material.hpp"

#include <Eigen/Core>

#include <array>

namespace neurosim::fem {

using TetNodes = std::array<Eigen::Vector3d, 4>;      // rest positions, unit m
using ElementMatrix = Eigen::Matrix<double, 12, 12>;  // unit N/m; dof 3*a+axis, a local node
using ElementVector = Eigen::Matrix<double, 12, 1>;

// Shape-function gradients and volume of one tetrahedron.
struct TetGeometry {
  Eigen::Matrix<double, 4, 3> gradients;  // row a: grad N_a, unit 1/m
  double volume_m3{0.0};                  // > 0
};

// Tetrahedra with volume <= kDegenerateVolumeRatio * (longest edge)^3 are refused.
inline constexpr double kDegenerateVolumeRatio = 1e-12;

// Throws std::invalid_argument naming `element_id` if a coordinate is non-finite, the tetrahedron
// is inverted (negative volume) or degenerate.
TetGeometry tet_geometry(const TetNodes& x, int element_id = -1);

// B (6x12): Voigt strain (xx, yy, zz, gamma_xy, gamma_yz, gamma_zx) = B u.
Eigen::Matrix<double, 6, 12> strain_displacement(const TetGeometry& g);

// K_e = V B^T D B (unit N/m), written in the closed isotropic form
// K_ab = V (lambda g_a g_b^T + mu g_b g_a^T + mu (g_a . g_b) I): no 6x6 products in assembly.
void tet_stiffness(const TetGeometry& g, double lambda_pa, double mu_pa, ElementMatrix& k);

// The 3x3 block K_ab of that formula: out[i][j] = vl ga_i gb_j + vm gb_i ga_j + vm (ga.gb) d_ij
// with vl = V lambda, vm = V mu (unit N/m). Shared by tet_stiffness and the assembler's
// scatter loop, which never forms the 12x12 matrix.
inline void tet_stiffness_block(const double* ga, const double* gb, double vl, double vm,
                                double out[3][3]) {
  const double dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      out[i][j] = vl * ga[i] * gb[j] + vm * gb[i] * ga[j];
    }
  }
  for (int i = 0; i < 3; ++i) {
    out[i][i] += vm * dot;
  }
}
ElementMatrix tet_stiffness(const TetNodes& x, const Material& material, int element_id = -1);

// Strain energy 1/2 V eps^T D eps (unit J) for nodal displacements u (m), via B and D.
double tet_strain_energy(const TetNodes& x, const Material& material, const ElementVector& u_m,
                         int element_id = -1);

// Shape measures of one tetrahedron (no validity check: slivers and inverted ones are reported).
struct TetQuality {
  double volume_m3{0.0};         // signed
  double mean_ratio{0.0};        // 6 sqrt(2) V / l_rms^3: 1 regular, -> 0 for slivers
  double min_dihedral_deg{0.0};  // smallest dihedral angle, degrees
  double max_dihedral_deg{0.0};  // largest dihedral angle, degrees
  double longest_edge_m{0.0};
  double shortest_edge_m{0.0};
};
TetQuality tet_quality(const TetNodes& x);

}  // namespace neurosim::fem
