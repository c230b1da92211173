#include "server/fem/elastic_law.hpp"

#include "server/fem/polar_decomposition.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

LawConstants LawConstants::of(const Material& material) {
  material.validate();
  const double e = material.youngs_modulus_pa, nu = material.poisson_ratio;
  LawConstants c;
  c.lambda_pa = material.lame_lambda_pa();
  c.mu_pa = material.shear_modulus_pa();
  c.c10_pa = e / (4.0 * (1.0 + nu));
  c.d1_per_pa = 6.0 * (1.0 - 2.0 * nu) / e;
  return c;
}

namespace {

using Mat3 = Eigen::Matrix3d;

// ---- LINEAR ----------------------------------------------------------------------------------
double linear_energy(const LawConstants& c, const Mat3& f) {
  const Mat3 eps = 0.5 * (f + f.transpose()) - Mat3::Identity();
  const double tr = eps.trace();
  return c.mu_pa * eps.squaredNorm() + 0.5 * c.lambda_pa * tr * tr;
}
Mat3 linear_stress(const LawConstants& c, const Mat3& f) {
  const Mat3 eps = 0.5 * (f + f.transpose()) - Mat3::Identity();
  return 2.0 * c.mu_pa * eps + c.lambda_pa * eps.trace() * Mat3::Identity();
}
Mat3 linear_dstress(const LawConstants& c, const Mat3& df) {
  return c.mu_pa * (df + df.transpose()) + c.lambda_pa * df.trace() * Mat3::Identity();
}

// ---- COROTATIONAL ----------------------------------------------------------------------------
double corot_energy(const LawConstants& c, const RotationVariantSvd& s) {
  const Eigen::Vector3d d = s.sigma - Eigen::Vector3d::Ones();
  const double tr = d.sum();
  return c.mu_pa * d.squaredNorm() + 0.5 * c.lambda_pa * tr * tr;
}
Mat3 corot_stress(const LawConstants& c, const RotationVariantSvd& s, const Mat3& f) {
  const Mat3 r = s.u * s.v.transpose();
  return 2.0 * c.mu_pa * (f - r) + c.lambda_pa * (s.sigma.sum() - 3.0) * r;
}
// dR = U W V^T with W skew, W_ij = (M_ij - M_ji) / (sigma_i + sigma_j), M = U^T dF V.
Mat3 corot_dstress(const LawConstants& c, const RotationVariantSvd& s, const Mat3& df) {
  const Mat3 r = s.u * s.v.transpose();
  const Mat3 m = s.u.transpose() * df * s.v;
  Mat3 w = Mat3::Zero();
  for (int i = 0; i < 3; ++i) {
    for (int j = i + 1; j < 3; ++j) {
      // sigma_i + sigma_j >= 0 (only sigma_2 may be negative and |sigma_2| <= sigma_i); zero
      // only for a collapsed element, where the rotation rate is undefined: held finite.
      const double denom = std::max(s.sigma(i) + s.sigma(j), 1e-12);
      w(i, j) = (m(i, j) - m(j, i)) / denom;
      w(j, i) = -w(i, j);
    }
  }
  const Mat3 dr = s.u * w * s.v.transpose();
  return 2.0 * c.mu_pa * (df - dr) + c.lambda_pa * (r.cwiseProduct(df).sum() * r +
                                                    (s.sigma.sum() - 3.0) * dr);
}

// ---- NONLINEAR (neo-Hookean, F with det F > 0) -----------------------------------------------
double nh_energy(const LawConstants& c, const Mat3& f) {
  const double j = f.determinant();
  const double i1 = f.squaredNorm();
  return c.c10_pa * (std::pow(j, -2.0 / 3.0) * i1 - 3.0) + (j - 1.0) * (j - 1.0) / c.d1_per_pa;
}
Mat3 nh_stress(const LawConstants& c, const Mat3& f) {
  const double j = f.determinant();
  const double a = std::pow(j, -2.0 / 3.0);
  const double i1 = f.squaredNorm();
  const Mat3 finv_t = f.inverse().transpose();
  return 2.0 * c.c10_pa * a * (f - (i1 / 3.0) * finv_t) +
         (2.0 / c.d1_per_pa) * (j - 1.0) * j * finv_t;
}
Mat3 nh_dstress(const LawConstants& c, const Mat3& f, const Mat3& df) {
  const double j = f.determinant();
  const double a = std::pow(j, -2.0 / 3.0);
  const double i1 = f.squaredNorm();
  const Mat3 finv = f.inverse();
  const Mat3 finv_t = finv.transpose();
  const double tr_finv_df = (finv * df).trace();
  const double dj = j * tr_finv_df;
  const double da = -2.0 / 3.0 * a * tr_finv_df;
  const double di1 = 2.0 * f.cwiseProduct(df).sum();
  const Mat3 dfinv_t = -finv_t * df.transpose() * finv_t;
  const double k = 2.0 / c.d1_per_pa;
  return 2.0 * c.c10_pa * (da * f + a * df) -
         (2.0 / 3.0) * c.c10_pa * ((da * i1 + a * di1) * finv_t + a * i1 * dfinv_t) +
         k * ((2.0 * j - 1.0) * dj * finv_t + (j * j - j) * dfinv_t);
}

// Clamped F^ when the neo-Hookean law must not be evaluated at F itself.
bool nh_clamp(const Mat3& f, Mat3& f_hat) {
  if (f.determinant() >= kStretchCheckJ) {
    return false;
  }
  RotationVariantSvd s = rotation_variant_svd(f);
  if (s.sigma.minCoeff() >= kMinStretch) {
    return false;
  }
  s.sigma = s.sigma.cwiseMax(kMinStretch);
  f_hat = s.u * s.sigma.asDiagonal() * s.v.transpose();
  return true;
}

template <typename DStress>
void tangent_columns(DStress&& dstress, StressTangent& dp_df) {
  for (int l = 0; l < 3; ++l) {
    for (int k = 0; k < 3; ++k) {
      Mat3 df = Mat3::Zero();
      df(k, l) = 1.0;
      const Mat3 dp = dstress(df);
      dp_df.col(k + 3 * l) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dp.data());
    }
  }
  dp_df = 0.5 * (dp_df + dp_df.transpose()).eval();  // symmetric up to round-off: made exact
}

void project_to_psd(StressTangent& dp_df) {
  const Eigen::SelfAdjointEigenSolver<StressTangent> eig(dp_df);
  const Eigen::Matrix<double, 9, 1> lambda = eig.eigenvalues().cwiseMax(0.0);
  dp_df = eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
}

void check_finite(const Mat3& f) {
  if (!f.allFinite()) {
    throw std::invalid_argument("elastic law: non-finite deformation gradient");
  }
}

}  // namespace

double energy_density(Tier tier, const LawConstants& c, const Mat3& f, LawEvaluation* eval) {
  check_finite(f);
  switch (tier) {
    case Tier::kLinear: return linear_energy(c, f);
    case Tier::kCorotational: return corot_energy(c, rotation_variant_svd(f));
    case Tier::kNonlinear: {
      Mat3 f_hat;
      const bool clamped = nh_clamp(f, f_hat);
      if (eval) eval->clamped = clamped;
      if (!clamped) return nh_energy(c, f);
      return nh_energy(c, f_hat) + nh_stress(c, f_hat).cwiseProduct(f - f_hat).sum();
    }
  }
  throw std::invalid_argument("energy_density: unknown tier");
}

Mat3 first_piola(Tier tier, const LawConstants& c, const Mat3& f, LawEvaluation* eval) {
  check_finite(f);
  switch (tier) {
    case Tier::kLinear: return linear_stress(c, f);
    case Tier::kCorotational: return corot_stress(c, rotation_variant_svd(f), f);
    case Tier::kNonlinear: {
      Mat3 f_hat;
      const bool clamped = nh_clamp(f, f_hat);
      if (eval) eval->clamped = clamped;
      return nh_stress(c, clamped ? f_hat : f);
    }
  }
  throw std::invalid_argument("first_piola: unknown tier");
}

void stress_tangent(Tier tier, const LawConstants& c, const Mat3& f, bool project_psd,
                    StressTangent& dp_df, LawEvaluation* eval) {
  check_finite(f);
  switch (tier) {
    case Tier::kLinear:
      tangent_columns([&](const Mat3& df) { return linear_dstress(c, df); }, dp_df);
      return;  // constant and positive definite for a valid material: nothing to project
    case Tier::kCorotational: {
      const RotationVariantSvd s = rotation_variant_svd(f);
      tangent_columns([&](const Mat3& df) { return corot_dstress(c, s, df); }, dp_df);
      break;
    }
    case Tier::kNonlinear: {
      Mat3 f_hat;
      const bool clamped = nh_clamp(f, f_hat);
      if (eval) eval->clamped = clamped;
      const Mat3& at = clamped ? f_hat : f;
      tangent_columns([&](const Mat3& df) { return nh_dstress(c, at, df); }, dp_df);
      project_psd = project_psd || clamped;
      break;
    }
  }
  if (project_psd) {
    project_to_psd(dp_df);
  }
}

}  // namespace neurosim::fem
