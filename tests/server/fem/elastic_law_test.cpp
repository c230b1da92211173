// The three stress laws checked against finite differences (P = dW/dF, dP/dF = d P), against
// each other for small strain (consistency of the linearization), and on the hard cases: a
// rigid rotation, an inverted element, nu = 0.499.
#include "server/fem/elastic_law.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <cmath>
#include <random>

namespace neurosim::fem {
namespace {

// The laws take the displacement gradient H = F - I.
Eigen::Matrix3d H(const Eigen::Matrix3d& f) { return f - Eigen::Matrix3d::Identity(); }

const Tier kTiers[] = {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear};
const LawConstants kBrain = LawConstants::of({3000.0, 0.45, "brain"});

Eigen::Matrix3d random_gradient(unsigned seed, double amplitude) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::Matrix3d h;
  for (int i = 0; i < 9; ++i) h.data()[i] = u(rng);
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(2.0 * u(rng), Eigen::Vector3d(u(rng), u(rng), 1.0).normalized()).matrix();
  return r * (Eigen::Matrix3d::Identity() + amplitude * h);
}

TEST(FemElasticLaw, NeoHookeanConstantsAreCalculixs) {
  const LawConstants c = LawConstants::of({1.0e6, 0.4, "cube"});
  EXPECT_NEAR(c.c10_pa, 1.0e6 / (4.0 * 1.4), 1e-9);
  EXPECT_NEAR(c.d1_per_pa, 6.0 * 0.2 / 1.0e6, 1e-20);
  EXPECT_NEAR(c.c10_pa, c.mu_pa / 2.0, 1e-9);
  const double bulk = 1.0e6 / (3.0 * (1.0 - 0.8));
  EXPECT_NEAR(c.d1_per_pa, 2.0 / bulk, 1e-20);
  EXPECT_THROW(LawConstants::of({1.0e6, 0.5, "bad"}), std::invalid_argument);
}

TEST(FemElasticLaw, StressIsTheGradientOfTheEnergy) {
  for (Tier tier : kTiers) {
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const Eigen::Matrix3d f = random_gradient(seed, 0.25);
      const Eigen::Matrix3d p = first_piola(tier, kBrain, H(f));
      Eigen::Matrix3d fd;
      const double h = 1e-6;
      for (int i = 0; i < 9; ++i) {
        Eigen::Matrix3d fp = f, fm = f;
        fp.data()[i] += h;
        fm.data()[i] -= h;
        fd.data()[i] = (energy_density(tier, kBrain, H(fp)) - energy_density(tier, kBrain, H(fm))) /
                       (2.0 * h);
      }
      EXPECT_LT((fd - p).norm(), 1e-6 * p.norm()) << tier_name(tier) << " seed " << seed;
    }
  }
}

TEST(FemElasticLaw, ClampedStressIsTheGradientOfTheClampedEnergy) {
  // Inverted and nearly collapsed elements: the clamped neo-Hookean energy keeps P = dW/dF,
  // so Newton's line search sees a consistent potential.
  const Eigen::Matrix3d r = Eigen::AngleAxisd(0.4, Eigen::Vector3d(1, -1, 2).normalized()).matrix();
  for (const Eigen::Vector3d& stretches :
       {Eigen::Vector3d(1.1, 0.9, -0.3), Eigen::Vector3d(1.2, 0.05, 0.5),
        Eigen::Vector3d(0.08, 0.06, 1.3)}) {
    const Eigen::Matrix3d f = r * stretches.asDiagonal();
    LawEvaluation eval;
    const Eigen::Matrix3d p = first_piola(Tier::kNonlinear, kBrain, H(f), &eval);
    EXPECT_TRUE(eval.clamped);
    Eigen::Matrix3d fd;
    const double h = 1e-7;
    for (int i = 0; i < 9; ++i) {
      Eigen::Matrix3d fp = f, fm = f;
      fp.data()[i] += h;
      fm.data()[i] -= h;
      fd.data()[i] = (energy_density(Tier::kNonlinear, kBrain, H(fp)) -
                      energy_density(Tier::kNonlinear, kBrain, H(fm))) /
                     (2.0 * h);
    }
    EXPECT_LT((fd - p).norm(), 1e-5 * p.norm()) << stretches.transpose();
  }
}

TEST(FemElasticLaw, TangentIsTheDerivativeOfTheStress) {
  for (Tier tier : kTiers) {
    for (unsigned seed = 1; seed <= 5; ++seed) {
      const Eigen::Matrix3d f = random_gradient(seed, 0.3);
      StressTangent c;
      stress_tangent(tier, kBrain, H(f), false, c);
      StressTangent fd;
      const double h = 1e-6;
      for (int i = 0; i < 9; ++i) {
        Eigen::Matrix3d fp = f, fm = f;
        fp.data()[i] += h;
        fm.data()[i] -= h;
        const Eigen::Matrix3d dp = (first_piola(tier, kBrain, H(fp)) - first_piola(tier, kBrain, H(fm))) /
                                   (2.0 * h);
        fd.col(i) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(dp.data());
      }
      EXPECT_LT((fd - c).norm(), 1e-6 * c.norm()) << tier_name(tier) << " seed " << seed;
    }
  }
}

TEST(FemElasticLaw, RigidRotationIsStressFreeExceptInTheLinearTier) {
  const Eigen::Matrix3d r = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()).matrix();
  EXPECT_LT(first_piola(Tier::kCorotational, kBrain, H(r)).norm(), 1e-12 * kBrain.mu_pa);
  EXPECT_LT(first_piola(Tier::kNonlinear, kBrain, H(r)).norm(), 1e-12 * kBrain.mu_pa);
  EXPECT_NEAR(energy_density(Tier::kNonlinear, kBrain, H(r)), 0.0, 1e-12 * kBrain.mu_pa);
  // The linear law sees a 90 degree rotation as a strain of order 1.
  EXPECT_GT(first_piola(Tier::kLinear, kBrain, H(r)).norm(), 0.5 * kBrain.mu_pa);
}

TEST(FemElasticLaw, TiersAgreeForSmallStrain) {
  for (unsigned seed = 1; seed <= 5; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    Eigen::Matrix3d h;
    for (int i = 0; i < 9; ++i) h.data()[i] = u(rng);
    // H itself is given (not F - I), so strains of 1e-9 keep their precision in every law.
    const double eps = 1e-9;
    const Eigen::Matrix3d hs = eps * h;
    const Eigen::Matrix3d p_lin = first_piola(Tier::kLinear, kBrain, hs);
    for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
      // Differences are second order in eps: relative 1e-6 is met with a wide margin.
      EXPECT_LT((first_piola(tier, kBrain, hs) - p_lin).norm(), 1e-6 * p_lin.norm())
          << tier_name(tier);
      EXPECT_NEAR(energy_density(tier, kBrain, hs), energy_density(Tier::kLinear, kBrain, hs),
                  1e-6 * energy_density(Tier::kLinear, kBrain, hs))
          << tier_name(tier);
      StressTangent c_lin, c;
      stress_tangent(Tier::kLinear, kBrain, hs, false, c_lin);
      stress_tangent(tier, kBrain, hs, false, c);
      EXPECT_LT((c - c_lin).norm(), 1e-6 * c_lin.norm()) << tier_name(tier);
    }
  }
}

TEST(FemElasticLaw, InvertedElementGetsFiniteRestoringStress) {
  const LawConstants nearly_incompressible = LawConstants::of({3000.0, 0.499, "brain"});
  // Collapsed through its z face: det F < 0.
  const Eigen::Matrix3d f = Eigen::Vector3d(1.05, 1.05, -0.3).asDiagonal();
  for (const LawConstants& c : {kBrain, nearly_incompressible}) {
    for (Tier tier : kTiers) {
      LawEvaluation eval;
      const Eigen::Matrix3d p = first_piola(tier, c, H(f), &eval);
      ASSERT_TRUE(p.allFinite()) << tier_name(tier);
      ASSERT_TRUE(std::isfinite(energy_density(tier, c, H(f)))) << tier_name(tier);
      StressTangent t;
      stress_tangent(tier, c, H(f), false, t);
      ASSERT_TRUE(t.allFinite()) << tier_name(tier);
      // Moving F towards the rest state lowers the energy: the stress pushes the element back.
      const Eigen::Matrix3d towards_rest = Eigen::Matrix3d::Identity() - f;
      EXPECT_LT(p.cwiseProduct(towards_rest).sum(), 0.0) << tier_name(tier);
      if (tier == Tier::kNonlinear) {
        EXPECT_TRUE(eval.clamped);
        // The clamped tangent is symmetric; projected (project_psd, the solver's fallback when
        // the exact tangent is not positive definite) it is positive semidefinite.
        EXPECT_LT((t - t.transpose()).cwiseAbs().maxCoeff(), 1e-6 * t.cwiseAbs().maxCoeff());
        StressTangent tp;
        stress_tangent(tier, c, H(f), true, tp);
        const Eigen::SelfAdjointEigenSolver<StressTangent> eig(tp);
        EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-9 * eig.eigenvalues().maxCoeff());
        // Unprojected, it is the derivative of the clamped stress (central differences).
        const double step = 1e-6;
        for (int col = 0; col < 9; ++col) {
          Eigen::Matrix3d df = Eigen::Matrix3d::Zero();
          df(col % 3, col / 3) = 1.0;
          const Eigen::Matrix3d dp =
              (first_piola(tier, c, H(f + step * df)) - first_piola(tier, c, H(f - step * df))) /
              (2.0 * step);
          for (int row = 0; row < 9; ++row) {
            EXPECT_NEAR(t(row, col), dp(row % 3, row / 3), 1e-4 * t.cwiseAbs().maxCoeff())
                << "row " << row << " col " << col;
          }
        }
      }
    }
  }
  // Exactly flat (det F = 0) is also finite.
  const Eigen::Matrix3d flat = Eigen::Vector3d(1.0, 1.0, 0.0).asDiagonal();
  for (Tier tier : kTiers) {
    EXPECT_TRUE(first_piola(tier, kBrain, H(flat)).allFinite()) << tier_name(tier);
  }
}

TEST(FemElasticLaw, UnclampedElementIsExactNeoHookean) {
  // Compressed to J = 0.45 with all stretches above the clamp: no clamping.
  const Eigen::Matrix3d f = Eigen::Vector3d(0.7, 0.8, 0.8).asDiagonal();
  LawEvaluation eval;
  first_piola(Tier::kNonlinear, kBrain, H(f), &eval);
  EXPECT_FALSE(eval.clamped);
  // Uniaxial closed form for the diagonal F: P_xx = 2 C10 J^-2/3 (l1 - I1/(3 l1)) + 2/D1 (J-1) J/l1
  const double l1 = 0.7, j = 0.7 * 0.8 * 0.8, i1 = 0.49 + 0.64 + 0.64;
  const double p_xx = 2.0 * kBrain.c10_pa * std::pow(j, -2.0 / 3.0) * (l1 - i1 / (3.0 * l1)) +
                      2.0 / kBrain.d1_per_pa * (j - 1.0) * j / l1;
  EXPECT_NEAR(first_piola(Tier::kNonlinear, kBrain, H(f))(0, 0), p_xx, 1e-9 * std::abs(p_xx));
}

TEST(FemElasticLaw, ProjectedTangentIsPositiveSemidefinite) {
  // Strong compression makes the neo-Hookean tangent indefinite (buckling directions).
  const Eigen::Matrix3d f = Eigen::Vector3d(0.55, 1.2, 1.2).asDiagonal();
  for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
    StressTangent t;
    stress_tangent(tier, kBrain, H(f), true, t);
    const Eigen::SelfAdjointEigenSolver<StressTangent> eig(t);
    EXPECT_GE(eig.eigenvalues().minCoeff(), -1e-9 * eig.eigenvalues().maxCoeff())
        << tier_name(tier);
  }
}

TEST(FemElasticLaw, TierNamesParse) {
  EXPECT_EQ(parse_tier("corotational"), Tier::kCorotational);
  EXPECT_EQ(parse_tier("NONLINEAR"), Tier::kNonlinear);
  EXPECT_EQ(parse_tier("Linear"), Tier::kLinear);
  EXPECT_FALSE(parse_tier("hyperelastic").has_value());
  EXPECT_STREQ(tier_name(Tier::kCorotational), "COROTATIONAL");
}

}  // namespace
}  // namespace neurosim::fem
