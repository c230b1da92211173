// Exposure: B's surface nodes outside A, counted against a plain inside test (the winding
// number) and the distance to A's box, node by node.
#include "server/fusion/exposure.hpp"

#include "fusion_fixtures.hpp"

#include <gtest/gtest.h>

#include <algorithm>

namespace neurosim::fusion {
namespace {

using test::structured_box;

TEST(fusion_exposure, InsideMeshHasNoExposedNodes) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 4, 4, 4);
  const auto b = structured_box(Vec3(0.3, 0.3, 0.3), Vec3(0.7, 0.7, 0.7), 2, 2, 2);
  const Exposure e = embedded_outside_host(a, b);
  EXPECT_EQ(e.surface_nodes, static_cast<int>(b.surface_vertices().size()));
  EXPECT_EQ(e.nodes_outside, 0);
  EXPECT_EQ(e.farthest_node, -1);
  EXPECT_EQ(e.max_distance_m, 0.0);
  ASSERT_EQ(e.outside.size(), b.num_vertices());
  EXPECT_EQ(std::count(e.outside.begin(), e.outside.end(), 1), 0);
}

TEST(fusion_exposure, NodesAboveTheTopAreCountedWithTheirDistance) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 4, 4, 4);
  // B from z = 0.5 to 1.3 on a 2 x 2 x 4 grid: its layers at z = 1.1 and 1.3 are outside A.
  const auto b = structured_box(Vec3(0.3, 0.3, 0.5), Vec3(0.7, 0.7, 1.3), 2, 2, 4);
  int expected = 0;
  for (int v : b.surface_vertices())
    if (b.vertices()[v].z() > 1.0 + 1e-9) ++expected;
  ASSERT_EQ(expected, 2 * 9 - 1);  // z = 1.1: the 8 on the ring; z = 1.3: the 9 of the top
  const Exposure e = embedded_outside_host(a, b);
  EXPECT_EQ(e.nodes_outside, expected);
  EXPECT_NEAR(e.max_distance_m, 0.3, 1e-12);
  ASSERT_GE(e.farthest_node, 0);
  EXPECT_NEAR(b.vertices()[e.farthest_node].z(), 1.3, 1e-12);
  // The flag per node: exactly B's surface nodes above A's top.
  ASSERT_EQ(e.outside.size(), b.num_vertices());
  std::vector<char> surface(b.num_vertices(), 0);
  for (int v : b.surface_vertices()) surface[v] = 1;
  for (std::size_t v = 0; v < b.num_vertices(); ++v)
    EXPECT_EQ(e.outside[v] != 0, surface[v] && b.vertices()[v].z() > 1.0 + 1e-9) << "node " << v;

  // A tolerance above the lower layer's distance (0.1) leaves only the top layer.
  ExposureOptions o;
  o.tolerance_m = 0.15;
  const Exposure top = embedded_outside_host(a, b, o);
  EXPECT_EQ(top.nodes_outside, 9);
  EXPECT_EQ(std::count(top.outside.begin(), top.outside.end(), 1), 9);
  o.tolerance_m = 0.35;
  EXPECT_EQ(embedded_outside_host(a, b, o).nodes_outside, 0);
  o.tolerance_m = -1.0;
  EXPECT_THROW(embedded_outside_host(a, b, o), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
