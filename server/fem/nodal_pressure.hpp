// The volumetric part of the average nodal pressure tetrahedron, anp-tet (Bonet & Burton 1998,
// "A simple average nodal pressure tetrahedral element for incompressible and nearly
// incompressible dynamic explicit applications"; Joldes, Wittek & Miller 2009, the element of
// NiftySim for brain). The strain energy of a mesh is split as
//
//   E = sum_e V_e [W(F_e) - K_e/2 theta_e^2]  +  sum_a V_a K_a/2 thetabar_a^2,
//
// where theta_e is the tier's volumetric strain of element e (elastic_law.hpp), V_a = sum_{e ni a}
// V_e / 4 the rest volume of node a, thetabar_a = sum_{e ni a} V_e theta_e / (4 V_a) the node's
// volume-averaged volumetric strain (for NONLINEAR, J_a - 1 with J_a the nodal volume ratio) and
// K_a = sum_{e ni a} V_e K_e / (4 V_a) its bulk modulus. The first sum is the deviatoric energy
// per element; the volumetric constraint is held once per node instead of once per element,
// which removes volumetric locking. The gradient is the "average nodal pressure" form: element e
// carries the pressure pbar_e = sum_{a in e} K_a thetabar_a / 4 in place of K_e theta_e. The
// Hessian adds sum_a V_a K_a q_a q_a^T (q_a = d thetabar_a / du), which couples the nodes of the
// elements around a: the stiffness pattern becomes node neighbours of neighbours.
// Constant after construction (rest geometry); evaluations write into caller-owned buffers.
#pragma once

#include "server/fem/assembly.hpp"
#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::fem {

class NodalPressure {
 public:
  // Throws std::invalid_argument for an invalid material map or a degenerate element (named).
  // A node that no tetrahedron uses has no volume and no volumetric term.
  NodalPressure(const mesh::TetMesh& mesh, const MaterialMap& materials);

  std::size_t num_nodes() const { return nodal_volume_m3_.size(); }
  std::size_t num_tets() const { return tets_.size(); }
  double nodal_volume_m3(int node) const { return nodal_volume_m3_[node]; }
  double nodal_bulk_pa(int node) const { return nodal_bulk_pa_[node]; }
  double element_bulk_pa(std::size_t tet) const { return element_bulk_pa_[tet]; }

  // thetabar_a from the elements' volumetric strains theta_e (both dimensionless).
  void nodal_strain(const std::vector<double>& element_theta, std::vector<double>& nodal_theta) const;
  // pbar_e = sum_{a in e} K_a thetabar_a / 4 (unit Pa) from the nodal strains.
  void element_pressure(const std::vector<double>& nodal_theta,
                        std::vector<double>& element_pressure_pa) const;
  // sum_a V_a K_a/2 thetabar_a^2, unit J.
  double energy(const std::vector<double>& nodal_theta) const;
  // Adds sum_a V_a K_a q_a q_a^T (unit N/m) into the value array of `k` (the pattern of
  // StiffnessAssembler(mesh, Element::kAnpTet or kSmoothedTet)), with w[e] row b = d theta_e / d u_b of local
  // node b (unit 1/m). q: caller-owned scratch (grows to 3 x the largest 1-ring once).
  void add_nodal_stiffness(const std::vector<Eigen::Matrix<double, 4, 3>>& w, SparseMatrix& k,
                           std::vector<double>& q) const;

  // Node adjacency (each node with itself), CSR sorted per node: of the tetrahedra (distance 1)
  // or its square (distance 2, the anp-tet stiffness pattern).
  static void adjacency(const mesh::TetMesh& mesh, int distance, std::vector<int>& offset,
                        std::vector<int>& nodes);

 private:
  std::vector<mesh::Tet> tets_;
  std::vector<double> element_volume_m3_;
  std::vector<double> element_bulk_pa_;
  std::vector<double> nodal_volume_m3_;
  std::vector<double> nodal_bulk_pa_;
  // Node -> tetrahedra (CSR) and, per incidence, the patch index of the tet's 4 local nodes.
  std::vector<int> node_tet_offset_, node_tet_;
  std::vector<int> patch_offset_, patch_;      // node -> its 1-ring (sorted), CSR
  std::vector<std::array<int, 4>> incidence_patch_;  // per incidence: patch index of local node
};

}  // namespace neurosim::fem
