// The paper's colour rule at the points that define it: grey at rest, red from one force unit,
// the blend between, |F| and not-finite forces.
#include "common/force_colour.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace {

using neurosim::common::force_colour;

void expect_rgb(const std::array<double, 3>& c, double r, double g, double b) {
  EXPECT_NEAR(c[0], r, 1e-15);
  EXPECT_NEAR(c[1], g, 1e-15);
  EXPECT_NEAR(c[2], b, 1e-15);
}

TEST(common_force_colour, GreyAtRestRedFromOneForceUnit) {
  expect_rgb(force_colour(0.0), 0.2, 0.2, 0.2);
  expect_rgb(force_colour(0.1), 0.3, 0.1, 0.1);
  expect_rgb(force_colour(0.8), 1.0, 0.0, 0.0);
  expect_rgb(force_colour(5.0), 1.0, 0.0, 0.0);
}

TEST(common_force_colour, TheForceUnitScalesAndTheSignDoesNotMatter) {
  expect_rgb(force_colour(2.0, 4.0), 0.7, 0.0, 0.0);
  expect_rgb(force_colour(-0.1), 0.3, 0.1, 0.1);
  expect_rgb(force_colour(std::numeric_limits<double>::quiet_NaN()), 1.0, 0.0, 0.0);
}

}  // namespace
