// The elasticity tiers as stress laws of the displacement gradient H = grad u (3x3,
// dimensionless; F = I + H is the deformation gradient). Every law is written in H so that
// small strains keep full relative precision (forming F = I + H first would lose eps / strain):
// strain-energy density W(F) (unit J/m^3 = Pa), first Piola-Kirchhoff stress P = dW/dF (Pa) and
// its derivative dP/dF (Pa). Every tier uses the same isotropic Material (E, nu).
//
//   LINEAR        small strain: eps = sym(F) - I, W = mu eps:eps + lambda/2 tr(eps)^2. Not
//                 invariant under rotation (a rigid rotation strains it).
//   COROTATIONAL  the linear law in the element's rotated frame: F = R S (polar, rotation-variant
//                 SVD so flat and inverted elements keep a proper rotation), W = mu |F - R|^2 +
//                 lambda/2 tr(S - I)^2, P = 2 mu (F - R) + lambda tr(S - I) R, which is exactly
//                 R K0 (R^T x - X) per element. dP/dF includes dR (exact tangent).
//   NONLINEAR     compressible neo-Hookean as CalculiX and Abaqus write it (*HYPERELASTIC,
//                 NEO HOOKE): W = C10 (J^-2/3 I1 - 3) + (J - 1)^2 / D1 with C10 = mu / 2 =
//                 E / (4 (1 + nu)) and D1 = 2 / K = 6 (1 - 2 nu) / E. Robust to inversion by
//                 clamping the principal stretches (Irving, Teran, Fedkiw 2004): when the
//                 smallest signed principal stretch s of F is below kMinStretch, the energy is
//                 W(s^) + dW/ds(s^) . (s - s^) with s^ = max(s, kMinStretch), a C1 extension
//                 whose exact gradient is P (so forces and energy stay consistent for the line
//                 search); its tangent (finite differences of P) is projected to positive
//                 semidefinite. Elements with J >= kStretchCheckJ are never
//                 clamped (all their stretches are far above kMinStretch in any deformation
//                 this simulator sees), so only nearly collapsed elements pay for the SVD; an
//                 unclamped element follows CalculiX's law exactly.
#pragma once

#include "server/fem/material.hpp"
#include "server/fem/tier.hpp"

#include <Eigen/Core>


namespace neurosim::fem {

inline constexpr double kMinStretch = 0.1;     // neo-Hookean clamp, dimensionless
inline constexpr double kStretchCheckJ = 0.5;  // det F below which stretches are checked

// Constants of one material for every tier.
struct LawConstants {
  double lambda_pa{0.0};  // Lame's first parameter, unit Pa
  double mu_pa{0.0};      // shear modulus, unit Pa
  double c10_pa{0.0};     // neo-Hookean C10 = mu / 2, unit Pa
  double d1_per_pa{0.0};  // neo-Hookean D1 = 2 / K, unit 1/Pa
  double bulk_pa{0.0};    // K = lambda + 2 mu / 3 = 2 / D1, unit Pa

  // Validates the material (Material::validate) and derives the constants.
  static LawConstants of(const Material& material);
  // The deviatoric part of the same law, W - K/2 theta^2 (volumetric_strain below): lambda
  // replaced by lambda - K = -2 mu / 3 (LINEAR, COROTATIONAL: mu |dev eps|^2) and 1 / D1 by 0
  // (NONLINEAR: C10 (J^-2/3 I1 - 3), clamped as the full law). Bounded below in every tier.
  LawConstants deviatoric() const;
};

using StressTangent = Eigen::Matrix<double, 9, 9>;  // dP/dF, vec column-major: i + 3 j

// What an evaluation did (for reports: clamped elements are not exact neo-Hookean).
struct LawEvaluation {
  bool clamped{false};  // NONLINEAR only: a principal stretch was clamped
};

// W(I + H), unit J/m^3.
double energy_density(Tier tier, const LawConstants& c, const Eigen::Matrix3d& h,
                      LawEvaluation* eval = nullptr);
// P(I + H), unit Pa.
Eigen::Matrix3d first_piola(Tier tier, const LawConstants& c, const Eigen::Matrix3d& h,
                            LawEvaluation* eval = nullptr);
// dP/dF at F = I + H (9x9, unit Pa), symmetric. project_psd: clip negative eigenvalues to zero (a descent
// direction for Newton far from equilibrium). A clamped neo-Hookean element's tangent (central
// differences of its C1 energy's stress) is projected only with project_psd.
void stress_tangent(Tier tier, const LawConstants& c, const Eigen::Matrix3d& h, bool project_psd,
                    StressTangent& dp_df, LawEvaluation* eval = nullptr);

// The volumetric strain theta(F) of a tier, whose energy K/2 theta^2 is the law's volumetric
// part (the rest, W - K/2 theta^2, is deviatoric): LINEAR tr H, COROTATIONAL tr(S - I) (signed
// stretches), NONLINEAR J - 1. The anp-tet element holds this part per node
// (nodal_pressure.hpp). gradient = d theta / dF (LINEAR I, COROTATIONAL R, NONLINEAR cof F).
struct VolumetricStrain {
  double theta{0.0};                                    // dimensionless
  Eigen::Matrix3d gradient{Eigen::Matrix3d::Identity()};  // dimensionless
};
VolumetricStrain volumetric_strain(Tier tier, const Eigen::Matrix3d& h);
// d^2 theta / dF^2 at F = I + H (9x9, vec column-major, dimensionless), symmetric.
void volumetric_hessian(Tier tier, const Eigen::Matrix3d& h, StressTangent& d2theta);

// Clips the negative eigenvalues of a symmetric dP/dF to zero.
void project_to_psd(StressTangent& dp_df);

}  // namespace neurosim::fem
