// The element barrier of smoothed-tet in NONLINEAR: an energy per tetrahedron, zero in every
// state a sound answer reaches, that keeps a single tetrahedron from collapsing or stretching
// without bound under the smoothing cells. smoothed-tet's deviatoric energy is a function of the
// cells' averaged gradients (smoothed_strain.hpp) and its volumetric energy of the nodes'
// averaged J (nodal_pressure.hpp): neither sees one tetrahedron inverting while its neighbours
// make up for it, so under a pushed probe the node cells let the tetrahedra beneath invert and
// the force fall while the tool goes deeper. The barrier, per tetrahedron with F = I + H,
//
//   psi(F) = k [ max(0, J_min - J)^3 + max(0, I1 / 3 - I1_max / 3)^3 ],   J = det F, I1 = |F|^2,
//
// is C2, zero (with its gradient and Hessian) while J >= J_min and I1 <= I1_max, and defined
// through inversion (both terms are polynomials of F). k = kStiffnessShare mu of the element's
// material (unit Pa). Thresholds: J_min = 0.25 (a tetrahedron of nearly incompressible tissue
// at a quarter of its volume), I1_max = 6 (a volume-preserving uniaxial stretch of 2.26, Green
// strain 2.06; a simple shear of 1.73): linear-tet and anp-tet under the 7 mm brain's 20 mm press
// stay below both (largest strain 0.62 / 0.86, nothing inverted). LINEAR has no barrier (its
// energy is quadratic: nothing to collapse into). Units: psi in J/m^3 (Pa), its gradient dpsi/dF
// in Pa.
#pragma once

#include "server/fem/elastic_law.hpp"

#include <Eigen/Core>

namespace neurosim::fem {

struct ElementBarrier {
  static constexpr double kMinJ = 0.25;          // dimensionless
  static constexpr double kMaxI1 = 6.0;          // dimensionless (3 at rest)
  static constexpr double kStiffnessShare = 10;  // k / mu, dimensionless

  double stiffness_pa{0.0};  // k, unit Pa

  static ElementBarrier of(const LawConstants& law);

  // Whether psi and its derivatives are nonzero at F = I + H.
  bool active(const Eigen::Matrix3d& h) const;
  // psi(I + H), unit J/m^3.
  double energy_density(const Eigen::Matrix3d& h) const;
  // dpsi/dF, unit Pa.
  Eigen::Matrix3d stress(const Eigen::Matrix3d& h) const;
  // d2psi/dF2 (vec column-major, unit Pa) added to dp_df.
  void add_tangent(const Eigen::Matrix3d& h, StressTangent& dp_df) const;
};

}  // namespace neurosim::fem
