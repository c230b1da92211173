#include "server/fem/elastic_law.hpp"

#include "server/fem/polar_decomposition.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>
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
  c.bulk_pa = c.lambda_pa + 2.0 / 3.0 * c.mu_pa;
  return c;
}

LawConstants LawConstants::deviatoric() const {
  LawConstants d = *this;
  d.lambda_pa = -2.0 / 3.0 * mu_pa;
  d.d1_per_pa = std::numeric_limits<double>::infinity();  // 1 / D1 = 0: no volumetric energy
  d.bulk_pa = 0.0;
  return d;
}

namespace {

using Mat3 = Eigen::Matrix3d;

// ---- LINEAR ----------------------------------------------------------------------------------
double linear_energy(const LawConstants& c, const Mat3& h) {
  const Mat3 eps = 0.5 * (h + h.transpose());
  const double tr = eps.trace();
  return c.mu_pa * eps.squaredNorm() + 0.5 * c.lambda_pa * tr * tr;
}
Mat3 linear_stress(const LawConstants& c, const Mat3& h) {
  const Mat3 eps = 0.5 * (h + h.transpose());
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
// Accurate path for det F >= kStretchCheckJ: S - I = sqrt(I + C') - I with C' = F^T F - I =
// H + H^T + H^T H formed from H, eigenvalues c_i mapped by c / (1 + sqrt(1 + c)) (no
// cancellation), R = F S^-1. Strains of 1e-9 keep full relative precision.
struct CorotAccurate {
  Mat3 s_minus_i;
  Mat3 r;
};
CorotAccurate corot_accurate(const Mat3& h) {
  const Mat3 cp = h + h.transpose() + h.transpose() * h;
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(cp);
  Eigen::Vector3d d;
  for (int i = 0; i < 3; ++i) {
    const double ci = eig.eigenvalues()(i);
    d(i) = ci / (1.0 + std::sqrt(1.0 + ci));
  }
  CorotAccurate a;
  a.s_minus_i = eig.eigenvectors() * d.asDiagonal() * eig.eigenvectors().transpose();
  a.r = (Mat3::Identity() + h) * (Mat3::Identity() + a.s_minus_i).inverse();
  return a;
}
double corot_energy_accurate(const LawConstants& c, const CorotAccurate& a) {
  const double tr = a.s_minus_i.trace();
  return c.mu_pa * a.s_minus_i.squaredNorm() + 0.5 * c.lambda_pa * tr * tr;
}
Mat3 corot_stress_accurate(const LawConstants& c, const CorotAccurate& a) {
  return a.r * (2.0 * c.mu_pa * a.s_minus_i + c.lambda_pa * a.s_minus_i.trace() * Mat3::Identity());
}

// dR = U W V^T with W skew, W_ij = (M_ij - M_ji) / (sigma_i + sigma_j), M = U^T dF V.
// R and 1 / (sigma_i + sigma_j) at one F, computed once per tangent.
struct CorotPoint {
  const RotationVariantSvd& s;
  Mat3 r;
  Mat3 inv_sum;  // (i, j), i < j: 1 / (sigma_i + sigma_j)
  explicit CorotPoint(const RotationVariantSvd& svd) : s(svd), r(svd.u * svd.v.transpose()) {
    for (int i = 0; i < 3; ++i) {
      for (int j = i + 1; j < 3; ++j) {
        // sigma_i + sigma_j >= 0 (only sigma_2 may be negative and |sigma_2| <= sigma_i); zero
        // only for a collapsed element, where the rotation rate is undefined: held finite.
        inv_sum(i, j) = 1.0 / std::max(s.sigma(i) + s.sigma(j), 1e-12);
      }
    }
  }
};
// dR: the rate of the polar decomposition's rotation R = U Vᵀ along dF.
Mat3 rotation_rate(const CorotPoint& p, const Mat3& df) {
  const Mat3 m = p.s.u.transpose() * df * p.s.v;
  Mat3 w = Mat3::Zero();
  for (int i = 0; i < 3; ++i) {
    for (int j = i + 1; j < 3; ++j) {
      w(i, j) = (m(i, j) - m(j, i)) * p.inv_sum(i, j);
      w(j, i) = -w(i, j);
    }
  }
  return p.s.u * w * p.s.v.transpose();
}
Mat3 corot_dstress(const LawConstants& c, const CorotPoint& p, const Mat3& df) {
  const Mat3 dr = rotation_rate(p, df);
  return 2.0 * c.mu_pa * (df - dr) + c.lambda_pa * (p.r.cwiseProduct(df).sum() * p.r +
                                                    (p.s.sigma.sum() - 3.0) * dr);
}

// ---- NONLINEAR (neo-Hookean, F with det F > 0) -----------------------------------------------
// From H (F = I + H) without cancellation: J - 1 = tr H + (tr^2 H - tr H^2) / 2 + det H,
// I1 - 3 = 2 tr H + |H|^2, J^-2/3 - 1 = expm1(-2/3 log1p(J - 1)), and P's deviatoric part
// 2 C10 J^-2/3 dev(b) F^-T with dev(b) = dev(H + H^T + H H^T).
double j_minus_one(const Mat3& h) {
  const double tr = h.trace();
  return tr + 0.5 * (tr * tr - (h * h).trace()) + h.determinant();
}
double nh_energy(const LawConstants& c, const Mat3& h) {
  const double jm1 = j_minus_one(h);
  const double am1 = std::expm1(-2.0 / 3.0 * std::log1p(jm1));  // J^-2/3 - 1
  const double i1m3 = 2.0 * h.trace() + h.squaredNorm();
  const double i1bar_m3 = 3.0 * am1 + (1.0 + am1) * i1m3;
  return c.c10_pa * i1bar_m3 + jm1 * jm1 / c.d1_per_pa;
}
// Cofactor matrix cof F = det(F) F^-T, a polynomial of F (defined for singular and inverted F).
Mat3 cofactor(const Mat3& f) {
  Mat3 c;
  c.col(0) = f.col(1).cross(f.col(2));
  c.col(1) = f.col(2).cross(f.col(0));
  c.col(2) = f.col(0).cross(f.col(1));
  return c;
}

// J^-2/3 (J = 1 + jm1) as std::pow(J, -2.0 / 3.0) to a few ulp. Near J = 1 (|J - 1| <= 0.1: every element of
// tissue under a tool) by the series 1 - x/3 + 2 x^2/9 of J^-1/3 (x = J - 1, error < 2e-4) and
// three Newton steps y <- y (4 - J y^3) / 3 on y^-3 = J (quadratic: < 1e-16), squared: the
// internal forces evaluate it once per smoothing cell and Newton evaluates them a few times per
// equilibrium update (glibc's pow was a fifth of their time). Elsewhere pow itself.
double j_pow_minus_two_thirds(double jm1) {
  const double j = 1.0 + jm1;
  if (!(std::abs(jm1) <= 0.1)) return std::pow(j, -2.0 / 3.0);
  double y = 1.0 + jm1 * (-1.0 / 3.0 + jm1 * (2.0 / 9.0));
  for (int k = 0; k < 3; ++k) y *= (4.0 - j * (y * y * y)) * (1.0 / 3.0);
  return y * y;
}
// P = 2 C10 J^-2/3 dev(b) F^-T + (2 / D1) (J - 1) J F^-T, with J F^-T = cof F (no inverse).
Mat3 nh_stress(const LawConstants& c, const Mat3& h) {
  const double jm1 = j_minus_one(h);
  const double j = 1.0 + jm1;
  const double a = j_pow_minus_two_thirds(jm1);
  const Mat3 bm = h + h.transpose() + h * h.transpose();  // b - I
  const Mat3 dev_b = bm - (bm.trace() / 3.0) * Mat3::Identity();
  const Mat3 cof = cofactor(Mat3::Identity() + h);  // J F^-T
  return (2.0 * c.c10_pa * a / j) * (dev_b * cof) + ((2.0 / c.d1_per_pa) * jm1) * cof;
}
// What dP depends on at one F, computed once per tangent (nine directional derivatives).
struct NhPoint {
  Mat3 f, finv, finv_t;
  double j, a, i1;
  explicit NhPoint(const Mat3& f_in)
      : f(f_in), finv(f_in.inverse()), finv_t(finv.transpose()), j(f_in.determinant()),
        a(std::pow(j, -2.0 / 3.0)), i1(f_in.squaredNorm()) {}
};
Mat3 nh_dstress(const LawConstants& c, const NhPoint& p, const Mat3& df) {
  const double tr_finv_df = (p.finv * df).trace();
  const double dj = p.j * tr_finv_df;
  const double da = -2.0 / 3.0 * p.a * tr_finv_df;
  const double di1 = 2.0 * p.f.cwiseProduct(df).sum();
  const Mat3 dfinv_t = -p.finv_t * df.transpose() * p.finv_t;
  const double k = 2.0 / c.d1_per_pa;
  return 2.0 * c.c10_pa * (da * p.f + p.a * df) -
         (2.0 / 3.0) * c.c10_pa * ((da * p.i1 + p.a * di1) * p.finv_t + p.a * p.i1 * dfinv_t) +
         k * ((2.0 * p.j - 1.0) * dj * p.finv_t + (p.j * p.j - p.j) * dfinv_t);
}

// Neo-Hookean in principal stretches (J = s0 s1 s2 > 0): gradient dW/ds and Hessian.
Eigen::Vector3d nh_principal_gradient(const LawConstants& c, const Eigen::Vector3d& sg) {
  const double j = sg.prod(), a = std::pow(j, -2.0 / 3.0), i1 = sg.squaredNorm();
  Eigen::Vector3d g;
  for (int i = 0; i < 3; ++i) {
    g(i) = c.c10_pa * a * (2.0 * sg(i) - 2.0 / 3.0 * i1 / sg(i)) +
           (2.0 / c.d1_per_pa) * (j - 1.0) * j / sg(i);
  }
  return g;
}
Mat3 nh_principal_hessian(const LawConstants& c, const Eigen::Vector3d& sg) {
  const double j = sg.prod(), a = std::pow(j, -2.0 / 3.0), i1 = sg.squaredNorm();
  Mat3 hs;
  for (int i = 0; i < 3; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double d = i == k ? 1.0 : 0.0;
      const double t1 = -2.0 / 3.0 * a / sg(k) * (2.0 * sg(i) - 2.0 / 3.0 * i1 / sg(i)) +
                        a * (2.0 * d - 4.0 / 3.0 * sg(k) / sg(i) + 2.0 / 3.0 * i1 * d / (sg(i) * sg(i)));
      const double t2 = (2.0 * j - 1.0) * j / (sg(k) * sg(i)) - (j * j - j) * d / (sg(i) * sg(i));
      hs(i, k) = c.c10_pa * t1 + (2.0 / c.d1_per_pa) * t2;
    }
  }
  return hs;
}

// Clamped evaluation (Irving, Teran, Fedkiw 2004, energy form): with s^ = max(s, kMinStretch),
// W^(s) = W(s^) + g(s^) . (s - s^), a C1 extension symmetric in s, so P = U diag(dW^/ds) V^T
// stays the exact gradient of W^ (the line search sees a consistent potential):
// dW^/ds_k = g_k(s^) + [k unclamped] sum_{j clamped} Hess_jk(s^) (s_j - s^_j).
struct NhClamp {
  bool clamped{false};
  RotationVariantSvd svd;
  Eigen::Vector3d s_hat;
};
NhClamp nh_clamp(const Mat3& h) {
  NhClamp r;
  const Mat3 f = Mat3::Identity() + h;
  if (f.determinant() >= kStretchCheckJ) {
    return r;
  }
  r.svd = rotation_variant_svd(f);
  if (r.svd.sigma.minCoeff() >= kMinStretch) {
    return r;
  }
  r.clamped = true;
  r.s_hat = r.svd.sigma.cwiseMax(kMinStretch);
  return r;
}
// As nh_clamp but always through the SVD (finite differences around a clamped state).
NhClamp nh_clamp_forced(const Mat3& h) {
  NhClamp r;
  r.svd = rotation_variant_svd(Mat3::Identity() + h);
  r.clamped = true;
  r.s_hat = r.svd.sigma.cwiseMax(kMinStretch);
  return r;
}
double nh_clamped_energy(const LawConstants& c, const NhClamp& k) {
  const Eigen::Vector3d& s = k.s_hat;
  const double j = s.prod();
  const double w = c.c10_pa * (std::pow(j, -2.0 / 3.0) * s.squaredNorm() - 3.0) +
                   (j - 1.0) * (j - 1.0) / c.d1_per_pa;
  return w + nh_principal_gradient(c, s).dot(k.svd.sigma - s);
}
Mat3 nh_clamped_stress(const LawConstants& c, const NhClamp& k) {
  Eigen::Vector3d g = nh_principal_gradient(c, k.s_hat);
  const Mat3 hs = nh_principal_hessian(c, k.s_hat);
  const Eigen::Vector3d excess = k.svd.sigma - k.s_hat;  // < 0 where clamped, 0 elsewhere
  Eigen::Vector3d g_ext = g;
  for (int kk = 0; kk < 3; ++kk) {
    if (excess(kk) != 0.0) continue;  // clamped direction: g_k(s^) only
    for (int j = 0; j < 3; ++j) {
      g_ext(kk) += hs(j, kk) * excess(j);
    }
  }
  return k.svd.u * g_ext.asDiagonal() * k.svd.v.transpose();
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

void check_finite(const Mat3& f) {
  if (!f.allFinite()) {
    throw std::invalid_argument("elastic law: non-finite deformation gradient");
  }
}

}  // namespace

void project_to_psd(StressTangent& dp_df) {
  const Eigen::SelfAdjointEigenSolver<StressTangent> eig(dp_df);
  const Eigen::Matrix<double, 9, 1> lambda = eig.eigenvalues().cwiseMax(0.0);
  dp_df = eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
}

VolumetricStrain volumetric_strain(Tier tier, const Mat3& h) {
  check_finite(h);
  VolumetricStrain v;
  switch (tier) {
    case Tier::kLinear:
      v.theta = h.trace();
      v.gradient.setIdentity();
      return v;
    case Tier::kCorotational: {
      const Mat3 f = Mat3::Identity() + h;
      if (f.determinant() >= kStretchCheckJ) {
        const CorotAccurate a = corot_accurate(h);
        v.theta = a.s_minus_i.trace();
        v.gradient = a.r;
      } else {
        const RotationVariantSvd s = rotation_variant_svd(f);
        v.theta = s.sigma.sum() - 3.0;
        v.gradient = s.u * s.v.transpose();
      }
      return v;
    }
    case Tier::kNonlinear:
      v.theta = j_minus_one(h);
      v.gradient = cofactor(Mat3::Identity() + h);
      return v;
  }
  throw std::invalid_argument("volumetric_strain: unknown tier");
}

void volumetric_hessian(Tier tier, const Mat3& h, StressTangent& d2theta) {
  check_finite(h);
  switch (tier) {
    case Tier::kLinear:
      d2theta.setZero();
      return;
    case Tier::kCorotational: {
      // d tr(S) / dF = R, so the Hessian is dR (the rotation rate of the polar decomposition).
      const RotationVariantSvd s = rotation_variant_svd(Mat3::Identity() + h);
      const CorotPoint p(s);
      tangent_columns(
          [&](const Mat3& df) { return rotation_rate(p, df); },
          d2theta);
      return;
    }
    case Tier::kNonlinear: {
      // cof is quadratic in F: cof(F + dF) = cof F + L(F, dF) + cof dF, L bilinear.
      const Mat3 f = Mat3::Identity() + h;
      const Mat3 cf = cofactor(f);
      tangent_columns([&](const Mat3& df) { return (cofactor(f + df) - cf - cofactor(df)).eval(); },
                      d2theta);
      return;
    }
  }
  throw std::invalid_argument("volumetric_hessian: unknown tier");
}

double energy_density(Tier tier, const LawConstants& c, const Mat3& h, LawEvaluation* eval) {
  check_finite(h);
  switch (tier) {
    case Tier::kLinear: return linear_energy(c, h);
    case Tier::kCorotational:
      if ((Mat3::Identity() + h).determinant() >= kStretchCheckJ) {
        return corot_energy_accurate(c, corot_accurate(h));
      }
      return corot_energy(c, rotation_variant_svd(Mat3::Identity() + h));
    case Tier::kNonlinear: {
      const NhClamp k = nh_clamp(h);
      if (eval) eval->clamped = k.clamped;
      return k.clamped ? nh_clamped_energy(c, k) : nh_energy(c, h);
    }
  }
  throw std::invalid_argument("energy_density: unknown tier");
}

Mat3 first_piola(Tier tier, const LawConstants& c, const Mat3& h, LawEvaluation* eval) {
  check_finite(h);
  switch (tier) {
    case Tier::kLinear: return linear_stress(c, h);
    case Tier::kCorotational: {
      const Mat3 f = Mat3::Identity() + h;
      if (f.determinant() >= kStretchCheckJ) {
        return corot_stress_accurate(c, corot_accurate(h));
      }
      return corot_stress(c, rotation_variant_svd(f), f);
    }
    case Tier::kNonlinear: {
      const NhClamp k = nh_clamp(h);
      if (eval) eval->clamped = k.clamped;
      return k.clamped ? nh_clamped_stress(c, k) : nh_stress(c, h);
    }
  }
  throw std::invalid_argument("first_piola: unknown tier");
}

void stress_tangent(Tier tier, const LawConstants& c, const Mat3& h, bool project_psd,
                    StressTangent& dp_df, LawEvaluation* eval) {
  check_finite(h);
  switch (tier) {
    case Tier::kLinear:
      tangent_columns([&](const Mat3& df) { return linear_dstress(c, df); }, dp_df);
      return;  // constant and positive definite for a valid material: nothing to project
    case Tier::kCorotational: {
      const RotationVariantSvd s = rotation_variant_svd(Mat3::Identity() + h);
      const CorotPoint point(s);
      tangent_columns([&](const Mat3& df) { return corot_dstress(c, point, df); }, dp_df);
      break;
    }
    case Tier::kNonlinear: {
      const NhClamp k = nh_clamp(h);
      if (eval) eval->clamped = k.clamped;
      if (!k.clamped) {
        const NhPoint point(Mat3::Identity() + h);
        tangent_columns([&](const Mat3& df) { return nh_dstress(c, point, df); }, dp_df);
      } else {
        // Nearly collapsed element (rare): central differences of the clamped stress, which
        // is C0 in F; only the Newton direction depends on it. Not projected here: projecting
        // one element's tangent makes Newton converge only linearly (a 10 mm press of the brain
        // at 5 mm cells in smoothed-tet stalled at a contraction of 0.9 per full Newton step with
        // one clamped cell: FemBrainPress.NonlinearCrushedCellsKeepNewtonSuperlinear); the solver
        // projects the whole tangent when this one is not positive definite or gives no descent
        // (project_psd).
        const double step = 1e-7 * (1.0 + h.norm());
        tangent_columns(
            [&](const Mat3& df) {
              return ((nh_clamped_stress(c, nh_clamp_forced(h + step * df)) -
                       nh_clamped_stress(c, nh_clamp_forced(h - step * df))) /
                      (2.0 * step))
                  .eval();
            },
            dp_df);
      }
      break;
    }
  }
  if (project_psd) {
    project_to_psd(dp_df);
  }
}

}  // namespace neurosim::fem
