// The tool's geometry on its own: the candidate grid against a brute-force box search, the
// penetration depth of a node against the sphere it is measured to, the closest point of a
// segment.
#include "server/interaction/tool_geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

namespace neurosim::interaction {
namespace {

using mesh::Vec3;

TEST(interaction_tool_geometry, GridQueriesHoldEveryPointInTheBoxOnce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::vector<Vec3> points(2000);
  for (auto& p : points) p = Vec3(u(rng), u(rng), u(rng));
  const PointGrid grid(points, 0.007);
  std::vector<int> found;
  for (int q = 0; q < 200; ++q) {
    const Vec3 c(u(rng), u(rng), u(rng));
    const double h = 0.001 + 0.02 * std::abs(u(rng)) / 0.05;
    const Vec3 lo = c - Vec3::Constant(h), hi = c + Vec3::Constant(h);
    found.clear();
    grid.query(lo, hi, found);
    const std::set<int> unique(found.begin(), found.end());
    ASSERT_EQ(unique.size(), found.size()) << "query " << q << ": a point returned twice";
    for (int i = 0; i < static_cast<int>(points.size()); ++i) {
      const Vec3& p = points[static_cast<std::size_t>(i)];
      const bool inside = (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all();
      if (inside) {
        ASSERT_TRUE(unique.count(i)) << "query " << q << ": point " << i << " in the box missed";
      }
    }
  }
  const PointGrid none(std::vector<Vec3>{}, 0.01);
  EXPECT_TRUE(none.empty());
}

// The contact step's reusable candidates rebuild a query's list from cells() and rank(): the
// points contains() says a box's cells hold, by rank, are exactly what query() lists, in order.
TEST(interaction_tool_geometry, QueryListsTheBoxCellsPointsByRank) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  std::vector<Vec3> points(1500);
  for (auto& p : points) p = Vec3(u(rng), u(rng), u(rng));
  const PointGrid grid(points, 0.006);
  std::vector<int> by_rank(points.size(), -1);
  for (int i = 0; i < static_cast<int>(points.size()); ++i) {
    const int r = grid.rank(i);
    ASSERT_TRUE(r >= 0 && r < static_cast<int>(points.size()) && by_rank[r] < 0) << "point " << i;
    by_rank[r] = i;
  }
  std::vector<int> found, rebuilt;
  for (int q = 0; q < 200; ++q) {
    const Vec3 c(u(rng), u(rng), u(rng));
    const double h = 0.0005 + 0.03 * std::abs(u(rng)) / 0.05;
    const Vec3 lo = c - Vec3::Constant(h), hi = c + Vec3::Constant(1.3 * h);
    found.clear();
    grid.query(lo, hi, found);
    const PointGrid::CellRange cells = grid.cells(lo, hi);
    rebuilt.clear();
    for (int i : by_rank)
      if (grid.contains(cells, i)) rebuilt.push_back(i);
    ASSERT_EQ(found, rebuilt) << "query " << q;
  }
  // A box beside the grid visits no cell.
  const PointGrid::CellRange none = grid.cells(Vec3::Constant(0.2), Vec3::Constant(0.3));
  for (int i = 0; i < static_cast<int>(points.size()); ++i) ASSERT_FALSE(grid.contains(none, i));
}

TEST(interaction_tool_geometry, NormalLineDepthIsTheSpheresReachAlongTheNormal) {
  const Vec3 x(0.01, 0.02, 0.03), n(0, 0, 1);
  const double r = 0.004;
  // Centre on the normal line above the node by s: depth r - s (positive while it overlaps).
  EXPECT_NEAR(normal_line_depth(x, n, x + 0.5 * r * n, r), 0.5 * r, 1e-15);
  EXPECT_NEAR(normal_line_depth(x, n, x + 2.0 * r * n, r), -r, 1e-15);
  // Off the line by e < r: the sphere's surface point on the line, sqrt(r^2 - e^2) above the centre.
  const double e = 0.6 * r, s = 0.3 * r;
  const Vec3 c = x + s * n + Vec3(e, 0, 0);
  EXPECT_NEAR(normal_line_depth(x, n, c, r), std::sqrt(r * r - e * e) - s, 1e-15);
  // The line misses the sphere.
  EXPECT_TRUE(std::isinf(normal_line_depth(x, n, x + Vec3(1.5 * r, 0, 0), r)));
  EXPECT_NEAR(height_above(x, n, x - 0.002 * n), 0.002, 1e-15);
}

TEST(interaction_tool_geometry, ClosestPointOfASegmentIsClampedToItsEnds) {
  const Vec3 p0(0, 0, 0), p1(1, 0, 0);
  EXPECT_TRUE(closest_on_segment(Vec3(0.3, 2, 0), p0, p1).isApprox(Vec3(0.3, 0, 0)));
  EXPECT_TRUE(closest_on_segment(Vec3(-1, 1, 0), p0, p1).isApprox(p0));
  EXPECT_TRUE(closest_on_segment(Vec3(3, -1, 0), p0, p1).isApprox(p1));
  EXPECT_TRUE(closest_on_segment(Vec3(3, -1, 0), p0, p0).isApprox(p0)) << "a point segment";
}

}  // namespace
}  // namespace neurosim::interaction
