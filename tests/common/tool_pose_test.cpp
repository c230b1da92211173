// The shaft axis against Eigen's rotation matrix of the same quaternion (an outside reference),
// and the fallbacks the viewers rely on.
#include "common/tool_pose.hpp"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace {

using neurosim::common::rotated_z;
using neurosim::common::shaft_axis;

TEST(common_tool_pose, TheAxisIsTheRotationMatrixThirdColumn) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int k = 0; k < 100; ++k) {
    Eigen::Quaterniond e(n(rng), n(rng), n(rng), n(rng));
    e.normalize();
    const double q[4] = {e.w(), e.x(), e.y(), e.z()};
    const Eigen::Vector3d ref = e.toRotationMatrix().col(2);
    const auto a = rotated_z(q);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(a[i], ref[i], 1e-14) << "quaternion " << k;
  }
}

TEST(common_tool_pose, AQuarterTurnAboutXPointsTheShaftAlongMinusY) {
  const double h = std::sqrt(0.5);
  const double q[4] = {h, h, 0.0, 0.0};
  const auto a = rotated_z(q);
  EXPECT_NEAR(a[0], 0.0, 1e-15);
  EXPECT_NEAR(a[1], -1.0, 1e-15);
  EXPECT_NEAR(a[2], 0.0, 1e-15);
}

TEST(common_tool_pose, ShaftAxisIsUnitAndFallsBackToPlusZ) {
  // Not unit: the rotation of q / |q| (normalising the quadratic formula's result instead would
  // point the shaft 41 degrees off, (0, -0.75, -0.66)).
  const double scaled[4] = {2.0, 2.0, 0.0, 0.0};
  const auto a = shaft_axis(scaled);
  EXPECT_NEAR(std::hypot(a[0], a[1], a[2]), 1.0, 1e-15);
  EXPECT_NEAR(a[1], -1.0, 1e-15);
  EXPECT_NEAR(a[2], 0.0, 1e-15);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const auto& q : {std::array<double, 4>{0, 0, 0, 0}, std::array<double, 4>{nan, 0, 0, 1}}) {
    const auto z = shaft_axis(q.data());
    EXPECT_EQ(z[0], 0.0);
    EXPECT_EQ(z[1], 0.0);
    EXPECT_EQ(z[2], 1.0);
  }
}

}  // namespace
