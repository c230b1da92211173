// Internal forces, strain energy and tangent stiffness of a tetrahedral mesh in one elasticity
// tier (elastic_law.hpp), for a displacement field u (3N, dof 3 node + axis, unit m). Constant
// after construction (the rest geometry and materials); every evaluation takes u and writes
// into caller-owned buffers. Linear tetrahedra: F = I + sum_a u_a grad(N_a)^T is constant per
// element, nodal force f_a = V P grad(N_a), element tangent V B^T (dP/dF) B. The laws take
// H = F - I, formed directly from u (full precision for small strains). With the anp-tet
// element (materials' element) the volumetric part of every tier's energy is held per node
// (nodal_pressure.hpp): the element keeps the law's deviatoric part (LawConstants::deviatoric),
// its stress gains the average nodal pressure pbar_e G_e and the tangent the nodal terms
// (pattern: neighbours of neighbours). With smoothed-tet the volumetric part is the same and
// the deviatoric part is held by the edge and node smoothing cells (smoothed_strain.hpp), the
// elements keeping only the pressure.
#pragma once

#include "server/fem/assembly.hpp"
#include "server/fem/elastic_law.hpp"
#include "server/fem/element_barrier.hpp"
#include "server/fem/material.hpp"
#include "server/fem/nodal_pressure.hpp"
#include "server/fem/quasi_linear_viscoelastic.hpp"
#include "server/fem/smoothed_strain.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <memory>
#include <vector>

namespace neurosim::fem {

// What one evaluation saw over all elements.
struct ElasticForcesReport {
  int clamped_elements{0};   // NONLINEAR: elements evaluated at clamped stretches
  int inverted_elements{0};  // det F <= 0
  int barrier_elements{0};   // smoothed-tet in NONLINEAR: elements the barrier holds
  // Largest principal Green-Lagrange strain magnitude over the elements (dimensionless).
  double max_strain{0.0};
};

class ElasticForces {
 public:
  // The scratch of the anp-tet and smoothed-tet evaluations, sized on first use and reused
  // (a caller that evaluates every step keeps one: no allocation after the first evaluation).
  // Without one, each evaluation allocates its own.
  struct Workspace {
    std::vector<VolumetricStrain> element;
    std::vector<double> theta, nodal_theta, pressure_pa;
    std::vector<Eigen::Matrix<double, 4, 3>> w;         // d theta_e / d u_b (1/m)
    std::vector<double> q;                              // nodal stiffness scratch
    std::vector<Eigen::Matrix<double, 9, 3>> cell;      // smoothed-tet tangent scratch
    // A relaxing mesh's step (quasi_linear_viscoelastic.hpp; linear-tet): every evaluation is then
    // the step's, P = gamma P_e + F S_h per element (energy gamma W_e + S_h : E, tangent
    // gamma dP_e/dF + dF S_h/dF). Null: elastic. Not owned.
    const ViscousStep* viscous{nullptr};
  };

  // Throws std::invalid_argument for an invalid material map or a degenerate element (named).
  ElasticForces(const mesh::TetMesh& mesh, const MaterialMap& materials, Tier tier);

  Tier tier() const { return tier_; }
  Element element() const { return element_; }
  int num_nodes() const { return num_nodes_; }
  int num_dofs() const { return 3 * num_nodes_; }
  std::size_t num_tets() const { return tets_.size(); }
  double volume_m3() const { return total_volume_m3_; }  // rest volume of the mesh, unit m^3

  // H = grad u = F - I of tetrahedron `tet` at displacement u (unit m), dimensionless.
  Eigen::Matrix3d displacement_gradient(std::size_t tet, const Eigen::VectorXd& u_m) const;

  // The law's second Piola-Kirchhoff stress S_e = F^-1 P(F) of tetrahedron `tet` at u_m
  // (symmetrized; linear-tet), unit Pa: what a relaxing mesh's internal variables integrate.
  Eigen::Matrix3d elastic_second_piola(std::size_t tet, const Eigen::VectorXd& u_m) const;

  // smoothed-tet in NONLINEAR: whether the element barrier acts on tetrahedron e at its
  // displacement gradient h (false for every other element and tier).
  bool barrier_holds(std::size_t e, const Eigen::Matrix3d& h) const {
    return !barriers_.empty() && barriers_[law_index_[e]].active(h);
  }
  // Total strain energy sum_e V_e W(F_e), unit J (smoothed-tet in NONLINEAR: with the element
  // barrier's).
  double energy(const Eigen::VectorXd& u_m, ElasticForcesReport* report = nullptr,
                Workspace* workspace = nullptr) const;
  // Internal nodal forces dE/du (3N, unit N): the forces the body needs applied to hold u.
  void internal_force(const Eigen::VectorXd& u_m, Eigen::VectorXd& f_n,
                      ElasticForcesReport* report = nullptr, Workspace* workspace = nullptr) const;
  // Tangent stiffness d^2E/du^2 (3N x 3N, unit N/m) in the assembler's pattern (k gets the
  // pattern on first use, values refilled in place). project_psd: every element tangent made
  // positive semidefinite (Newton far from equilibrium).
  void tangent(const Eigen::VectorXd& u_m, bool project_psd, SparseMatrix& k,
               ElasticForcesReport* report = nullptr, Workspace* workspace = nullptr) const;

  const StiffnessAssembler& assembler() const { return assembler_; }

 private:
  Tier tier_;
  Element element_{Element::kLinearTet};
  int num_nodes_{0};
  std::vector<mesh::Tet> tets_;
  std::vector<Eigen::Matrix<double, 4, 3>> gradients_;  // per tet, row a: grad N_a (1/m)
  std::vector<double> volume_m3_;
  double total_volume_m3_{0.0};
  std::vector<int> law_index_;  // per tet: index into laws_
  std::vector<LawConstants> laws_;  // anp-tet: their deviatoric parts
  // smoothed-tet in NONLINEAR: the element barrier per material (element_barrier.hpp); else
  // empty.
  std::vector<ElementBarrier> barriers_;
  StiffnessAssembler assembler_;
  std::unique_ptr<const NodalPressure> nodal_;      // anp-tet, smoothed-tet
  std::unique_ptr<const SmoothedStrain> smoothed_;  // smoothed-tet only

  // anp-tet, smoothed-tet: every element's volumetric strain and gradient, and its average
  // nodal pressure, into the workspace.
  void nodal_state(const Eigen::VectorXd& u_m, Workspace& s) const;

  void check_size(const Eigen::VectorXd& u_m, const char* what) const;
};

}  // namespace neurosim::fem
