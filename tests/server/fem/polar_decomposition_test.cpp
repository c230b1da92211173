// Rotation-variant SVD: proper rotations, F reconstructed, an inverted F keeps a rotation and
// gets a negative smallest stretch, flat and zero F stay finite.
#include "server/fem/polar_decomposition.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <Eigen/LU>

#include <limits>

namespace neurosim::fem {
namespace {

void expect_valid(const Eigen::Matrix3d& f) {
  const RotationVariantSvd s = rotation_variant_svd(f);
  EXPECT_NEAR(s.u.determinant(), 1.0, 1e-12);
  EXPECT_NEAR(s.v.determinant(), 1.0, 1e-12);
  EXPECT_LT((s.u.transpose() * s.u - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_LT((s.u * s.sigma.asDiagonal() * s.v.transpose() - f).norm(), 1e-12 * (1 + f.norm()));
  EXPECT_GE(s.sigma(0), s.sigma(1));
  EXPECT_GE(s.sigma(1), std::abs(s.sigma(2)));
  EXPECT_EQ(s.sigma(2) < 0.0, f.determinant() < 0.0);
  const Eigen::Matrix3d r = polar_rotation(f);
  EXPECT_NEAR(r.determinant(), 1.0, 1e-12);
}

TEST(FemPolarDecomposition, RotationOfAStretchedRotation) {
  const Eigen::Matrix3d r0 = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).matrix();
  Eigen::Matrix3d s0;
  s0 << 1.2, 0.1, 0.0, 0.1, 0.9, 0.05, 0.0, 0.05, 1.1;
  const Eigen::Matrix3d f = r0 * s0;
  expect_valid(f);
  EXPECT_LT((polar_rotation(f) - r0).norm(), 1e-12);
}

TEST(FemPolarDecomposition, InvertedElementKeepsAProperRotation) {
  const Eigen::Matrix3d r0 = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).matrix();
  const Eigen::Matrix3d f = r0 * Eigen::Vector3d(1.0, 1.0, -0.2).asDiagonal();  // z flipped
  expect_valid(f);
  const RotationVariantSvd s = rotation_variant_svd(f);
  EXPECT_NEAR(s.sigma(2), -0.2, 1e-12);
  EXPECT_LT((polar_rotation(f) - r0).norm(), 1e-12);  // the rotation, not a reflection
}

TEST(FemPolarDecomposition, FlatAndZeroGradientsStayFinite) {
  expect_valid(Eigen::Vector3d(1.0, 0.5, 0.0).asDiagonal());
  expect_valid(Eigen::Matrix3d::Zero());
  Eigen::Matrix3d rank1 = Eigen::Vector3d(1, 2, 3) * Eigen::RowVector3d(0.5, -1, 2);
  expect_valid(rank1);
  Eigen::Matrix3d bad = Eigen::Matrix3d::Identity();
  bad(1, 1) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(rotation_variant_svd(bad), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
