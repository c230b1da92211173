// Quasi-linear viscoelasticity (Fung 1981; the form of Miller's brain model) in the NONLINEAR
// tier: the second Piola-Kirchhoff stress is the hereditary integral of the hyperelastic one,
//   S(t) = int_{-inf}^{t} g(t - s) dS_e(s),  g(t) = g_inf + sum_i g_i exp(-t / tau_i)
// (fem/viscoelastic.hpp: g(0) = 1, the neo-Hookean constants are the instantaneous ones; bulk and
// shear relax alike, as in the LINEAR tier's model). With the internal variables
// h_i(t) = int e^{-(t-s)/tau_i} dS_e(s) per element (linear-tet: one quadrature point),
// S = g_inf S_e + sum_i g_i h_i, and over a step dt with S_e linear in time between the step
// times (the exponential integrator of Taylor, Pister & Goudreau 1970; Simo 1987; Puso & Weiss
// 1998 — exact for that input):
//   h_i,n+1 = E_i h_i,n + beta_i (S_e,n+1 - S_e,n),  E_i = e^{-dt/tau_i},
//   beta_i = (1 - E_i) / (dt / tau_i)  (1 at dt = 0),
// hence S_n+1 = gamma S_e(F_n+1) + S_h with the step's constants
//   gamma = g_inf + sum_i g_i beta_i = 1 - sum g_i + sum g_i beta_i,
//   S_h   = sum_i g_i (E_i h_i,n - beta_i S_e,n)  (per element, known before the step).
// In the first Piola-Kirchhoff stress the tier's law uses, P = F S = gamma P_e(F) + F S_h, the
// gradient of the step's potential gamma W_e(F) + S_h : E(F) (E = (F^T F - I) / 2, the
// Green-Lagrange strain), so Newton keeps its line search on a potential; the consistent tangent
// is gamma dP_e/dF + (dF S_h)/dF, the elastic one scaled by gamma plus the history stress's
// geometric term (ElasticForces with Workspace::viscous).
//
// A step at the time of the last committed one replaces it (as the LINEAR tier's history,
// interaction/viscoelastic_history.hpp): the internal variables go back to before it and the step
// is solved again with its dt; one instant has one state.
#pragma once

#include "server/fem/viscoelastic.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::fem {

class ElasticForces;

// What one step of a relaxing mesh adds to its elastic law (ElasticForces::Workspace::viscous).
struct ViscousStep {
  double gamma{1.0};  // dimensionless, in (g_inf, 1]
  std::vector<Eigen::Matrix3d> history_stress_pa;  // S_h per tetrahedron, symmetric, unit Pa
};

class QuasiLinearViscoelastic {
 public:
  // The kernel (validated, not empty) of the mesh of `forces` (NONLINEAR tier, linear-tet: one
  // quadrature point per element). Throws std::invalid_argument naming `what` otherwise (the
  // anp-tet and smoothed-tet elements hold parts of the energy per node and per smoothing cell,
  // whose internal variables are not implemented).
  QuasiLinearViscoelastic(const ElasticForces& forces, const Viscoelastic& kernel,
                          const std::string& what);

  // The step to t_n+1 = t_n + dt_s (dt_s >= 0, finite): gamma and S_h per element. dt_s = 0 after
  // a commit: that commit is taken back and its step solved again (see above); a step begun and
  // not committed leaves the committed state as it was.
  void begin(double dt_s);
  const ViscousStep& step() const { return step_; }
  // The step converged at u_m (the mesh's displacement, 3N, unit m): S_e,n+1 per element, the
  // internal variables advanced.
  void commit(const Eigen::VectorXd& u_m);

  // The part of the stress still to relax, max over elements of |sum_i g_i h_i| (Frobenius),
  // relative to the largest |S_e|; 0 at rest.
  double unrelaxed() const { return unrelaxed_; }  // computed by commit
  // Per element after the last commit: S_e and S = g_inf S_e + sum g_i h_i (unit Pa).
  const Eigen::Matrix3d& elastic_stress(std::size_t tet) const { return se_[tet]; }
  Eigen::Matrix3d stress(std::size_t tet) const;
  const Viscoelastic& kernel() const { return kernel_; }

 private:
  const ElasticForces& forces_;
  Viscoelastic kernel_;
  int num_terms_;
  std::size_t num_tets_;
  ViscousStep step_;
  std::vector<double> e_, beta_;  // per term, this step
  double dt_s_{0.0};
  // Committed: S_e per element, h_i per element and term (element-major); and the same before the
  // last commit (swapped in to replace it).
  std::vector<Eigen::Matrix3d> se_, h_, last_se_, last_h_;
  double last_dt_s_{0.0};
  bool has_last_{false}, taken_back_{false};
  double unrelaxed_{0.0}, last_unrelaxed_{0.0};
  void take_back();
};

}  // namespace neurosim::fem
