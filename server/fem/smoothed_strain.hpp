// The deviatoric part of the selective smoothed tetrahedron, smoothed-tet: the strain energy of
// a mesh of linear tetrahedra is
//
//   E = sum_c V_c W_dev(F_c)  +  sum_a V_a K_a/2 thetabar_a^2,
//
// the volumetric part per node as anp-tet (nodal_pressure.hpp) and the deviatoric part over
// smoothing cells c, each with the smoothed deformation gradient F_c = I + sum_{e in c} (V_e^c /
// V_c) H_e, the volume-weighted mean of the compatible gradients of its tetrahedra. The cells
// are those of the edge-based smoothed FEM (ES-FEM-T4: Nguyen-Thoi, Liu, Lam & Zhang 2009, every
// tetrahedron gives V_e / 6 to each of its six edges) and of the node-based one (NS-FEM: Liu,
// Nguyen-Thoi et al. 2009, V_e / 4 to each of its nodes), their energies mixed as in Liu,
// Nguyen-Thoi & Lam's alpha-FEM (2008): (1 - kNodeShare) edge cells + kNodeShare node cells.
// The compatible (linear-tet) energy is an upper bound of the stiffness, the node-smoothed one
// a lower bound; the edge-smoothed one is close to the first. Measured on the locking test's
// cantilever and indentation (C3D10 on the same mesh, nu = 0.45 ... 0.499, regular and jittered
// meshes): ES + NS volumetric alone 0.88 - 0.97, the half-half mix 0.99 - 1.05 of C3D10's
// compliance; the free patch keeps exactly the six rigid modes (the edge cells stabilise the node
// cells' low-energy modes). Cells never straddle two materials (a cell per edge or node and
// material), so every cell has one law. Constant after construction.
#pragma once

#include "server/fem/assembly.hpp"
#include "server/fem/elastic_law.hpp"
#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::fem {

class SmoothedStrain {
 public:
  // Share of the deviatoric energy on the node cells (alpha of alpha-FEM), dimensionless.
  static constexpr double kNodeShare = 0.5;

  // Throws std::invalid_argument for an invalid material map or a degenerate element (named).
  // `pattern`: the stiffness pattern the tangent is added into (StiffnessAssembler of
  // smoothed-tet: neighbours of neighbours, which holds every cell's node pairs).
  SmoothedStrain(const mesh::TetMesh& mesh, const MaterialMap& materials,
                 const SparseMatrix& pattern);

  int num_cells() const { return static_cast<int>(volume_m3_.size()); }
  int max_cell_nodes() const { return max_cell_nodes_; }
  // The cell's energy weight: its volume times its share (edge or node), unit m^3.
  double volume_m3(int cell) const { return volume_m3_[cell]; }
  // Index into the material map's materials.
  int material(int cell) const { return material_[cell]; }

  // H_c = F_c - I at displacement u (unit m), dimensionless.
  Eigen::Matrix3d displacement_gradient(int cell, const Eigen::VectorXd& u_m) const;
  // f_b += V_c P g_cb (unit N) for the cell's stress P (unit Pa).
  void add_force(int cell, const Eigen::Matrix3d& p_pa, Eigen::VectorXd& f_n) const;
  // K_bc += V_c G_b^T (dP/dF) G_c (unit N/m) into the value array of `k` (the constructor's
  // pattern). scratch: max_cell_nodes() entries (caller-owned, not resized here).
  void add_tangent(int cell, const StressTangent& dp_df,
                   std::vector<Eigen::Matrix<double, 9, 3>>& scratch, SparseMatrix& k) const;

 private:
  std::vector<double> volume_m3_;
  std::vector<int> material_;
  std::vector<int> node_offset_;  // cell -> its nodes (CSR, sorted)
  std::vector<int> nodes_;
  std::vector<Eigen::Vector3d> gradient_;  // per cell node: d F_c / d u_b = g_cb (1/m)
  // Per cell, per (row node i, column node j) (row-major i * n + j): offset of row 3 node_i in
  // column 3 node_j + axis of the pattern (the same for the three axes).
  std::vector<int> pair_offset_;  // cell -> first pair
  std::vector<int> pair_row_;
  int max_cell_nodes_{0};
};

}  // namespace neurosim::fem
