// smoothed-tet's element barrier in NONLINEAR (element_barrier.hpp): zero in sound states, its
// stress the derivative of its energy and its tangent the derivative of its stress (central
// differences) in crushed, inverted and overstretched tetrahedra, and a crushed tetrahedron
// pushed back.
#include "server/fem/element_barrier.hpp"

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace neurosim::fem {
namespace {

using Mat3 = Eigen::Matrix3d;

ElementBarrier barrier() {
  return ElementBarrier::of(LawConstants::of(Material{3000.0, 0.49, "brain"}));
}

// H of F = R diag(s) R'^T: a rotated stretch (s may hold a negative entry: inverted).
Mat3 stretched(const Eigen::Vector3d& s, double angle) {
  const Mat3 r = Eigen::AngleAxisd(angle, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Mat3 q = Eigen::AngleAxisd(0.7 * angle, Eigen::Vector3d(-2, 1, 1).normalized()).toRotationMatrix();
  return r * s.asDiagonal() * q.transpose() - Mat3::Identity();
}

TEST(ElementBarrier, ZeroInEverySoundState) {
  const ElementBarrier b = barrier();
  EXPECT_DOUBLE_EQ(b.stiffness_pa, ElementBarrier::kStiffnessShare * 3000.0 / (2.0 * 1.49));
  // Rest, a rigid rotation, a 40 % compression with bulging, a shear of 1.
  Mat3 shear = Mat3::Zero();
  shear(0, 1) = 1.0;
  for (const Mat3& h : {Mat3(Mat3::Zero()), stretched({1, 1, 1}, 2.0),
                        stretched({0.6, 1.29, 1.29}, 0.4), shear}) {
    EXPECT_FALSE(b.active(h));
    EXPECT_EQ(b.energy_density(h), 0.0);
    EXPECT_EQ(b.stress(h).norm(), 0.0);
    StressTangent t = StressTangent::Zero();
    b.add_tangent(h, t);
    EXPECT_EQ(t.norm(), 0.0);
  }
}

TEST(ElementBarrier, StressAndTangentAreTheDerivativesOfItsEnergyThroughInversion) {
  const ElementBarrier b = barrier();
  // Crushed (J = 0.1), flat (J = 0), inverted (J = -0.3), overstretched (I1 = 9.3), both.
  for (const Mat3& h : {stretched({0.2, 0.7, 0.72}, 0.3), stretched({0.0, 1.1, 0.9}, 1.1),
                        stretched({-0.3, 1.0, 1.0}, 0.5), stretched({2.9, 0.6, 0.6}, 0.8),
                        stretched({2.8, 0.05, 1.2}, 2.4)}) {
    ASSERT_TRUE(b.active(h));
    EXPECT_GT(b.energy_density(h), 0.0);
    const Mat3 p = b.stress(h);
    StressTangent t = StressTangent::Zero();
    b.add_tangent(h, t);
    const double step = 1e-6;
    for (int l = 0; l < 3; ++l) {
      for (int k = 0; k < 3; ++k) {
        Mat3 d = Mat3::Zero();
        d(k, l) = step;
        const double dw = (b.energy_density(h + d) - b.energy_density(h - d)) / (2.0 * step);
        EXPECT_NEAR(p(k, l), dw, 1e-6 * (1.0 + p.norm())) << "dpsi/dF(" << k << "," << l << ")";
        const Mat3 dp = (b.stress(h + d) - b.stress(h - d)) / (2.0 * step);
        const Eigen::Map<const Eigen::Matrix<double, 9, 1>> col(dp.data());
        EXPECT_LT((t.col(k + 3 * l) - col).norm(), 1e-6 * (1.0 + t.norm()));
      }
    }
    EXPECT_LT((t - t.transpose()).norm(), 1e-9 * t.norm());
    ASSERT_TRUE(t.allFinite());
  }
}

TEST(ElementBarrier, PushesACrushedTetrahedronOpenAndPullsAnOverstretchedOneIn) {
  const ElementBarrier b = barrier();
  // Along F's own direction of growing J (cof F) the energy falls; along growing I1 it grows.
  const Mat3 crushed = stretched({-0.2, 0.9, 0.9}, 0.7);
  const Mat3 f = Mat3::Identity() + crushed;
  const Mat3 cof = f.determinant() * f.inverse().transpose();
  EXPECT_LT((b.stress(crushed).cwiseProduct(cof)).sum(), 0.0);
  const Mat3 long_h = stretched({3.0, 0.6, 0.6}, 0.2);
  EXPECT_GT((b.stress(long_h).cwiseProduct(Mat3::Identity() + long_h)).sum(), 0.0);
}

TEST(ElementBarrier, RefusesANonPositiveShearModulus) {
  LawConstants law;
  law.mu_pa = 0.0;
  EXPECT_THROW(ElementBarrier::of(law), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
