// The tool's geometry on its own: the candidate grid against a brute-force box search, the
// penetration depth of a node against the sphere it is measured to, the closest point of a
// segment, the near field of a contact patch (against the tip's formula and Hertz's elliptic
// compliance) and the shaft's patch.
#include "server/interaction/tool_geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <stdexcept>
#include <vector>

namespace neurosim::interaction {
namespace {

using mesh::Vec3;

// n points drawn from u per coordinate (the grid tests' clouds; fixed seeds).
std::vector<Vec3> random_points(std::mt19937& rng, std::uniform_real_distribution<double>& u,
                                int n) {
  std::vector<Vec3> points(static_cast<std::size_t>(n));
  for (auto& p : points) p = Vec3(u(rng), u(rng), u(rng));
  return points;
}

TEST(interaction_tool_geometry, GridQueriesHoldEveryPointInTheBoxOnce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  const std::vector<Vec3> points = random_points(rng, u, 2000);
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
  const std::vector<Vec3> points = random_points(rng, u, 1500);
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

// A long tool's box against its axis: query_near lists query's points in query's order less
// some, keeps every point within the radius of the segment, and drops most of a tilted shaft's
// box (a 150 mm shaft's box holds far more of a surface than its capsule).
TEST(interaction_tool_geometry, QueryNearKeepsThePointsNearTheSegmentInQueryOrder) {
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  const std::vector<Vec3> points = random_points(rng, u, 3000);
  const PointGrid grid(points, 0.005);
  std::vector<int> all, near;
  std::size_t listed = 0, kept = 0;
  for (int q = 0; q < 200; ++q) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const double radius = 0.001 + 0.01 * std::abs(u(rng)) / 0.05;
    const Vec3 lo = a.cwiseMin(b) - Vec3::Constant(radius);
    const Vec3 hi = a.cwiseMax(b) + Vec3::Constant(radius);
    all.clear();
    near.clear();
    grid.query(lo, hi, all);
    grid.query_near(lo, hi, a, b, radius, near);
    // A subsequence of query's list ...
    std::size_t k = 0;
    for (int i : near) {
      while (k < all.size() && all[k] != i) ++k;
      ASSERT_LT(k, all.size()) << "query " << q << ": point " << i << " not in query's order";
      ++k;
    }
    // ... holding every listed point within the radius of the segment.
    const std::set<int> kept_set(near.begin(), near.end());
    for (int i : all) {
      const Vec3& p = points[static_cast<std::size_t>(i)];
      if ((p - closest_on_segment(p, a, b)).norm() <= radius) {
        ASSERT_TRUE(kept_set.count(i)) << "query " << q << ": point " << i << " near the axis dropped";
      }
    }
    listed += all.size();
    kept += near.size();
  }
  EXPECT_LT(static_cast<double>(kept), 0.5 * static_cast<double>(listed))
      << "query_near dropped little of the boxes: " << kept << " of " << listed;
  EXPECT_THROW(grid.query_near(Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), -1.0, near),
               std::invalid_argument);
}

// A tool's two boxes in one pass: query_ranks lists the union of query(tip box) and
// query_near(shaft box) as ranks, each point once, ascending (the grid's order), and alone
// (no second box) query's points as ranks.
TEST(interaction_tool_geometry, QueryRanksIsTheUnionOfTheTwoQueriesInRankOrder) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> u(-0.05, 0.05);
  const std::vector<Vec3> points = random_points(rng, u, 3000);
  const PointGrid grid(points, 0.005);
  std::vector<int> tip, shaft, ranks, alone;
  for (int q = 0; q < 200; ++q) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const double h = 0.002 + 0.01 * std::abs(u(rng)) / 0.05;
    const double radius = 0.001 + 0.01 * std::abs(u(rng)) / 0.05;
    const Vec3 lo = a - Vec3::Constant(h), hi = a + Vec3::Constant(h);
    const Vec3 near_lo = a.cwiseMin(b) - Vec3::Constant(radius);
    const Vec3 near_hi = a.cwiseMax(b) + Vec3::Constant(radius);
    tip.clear();
    shaft.clear();
    ranks.clear();
    alone.clear();
    grid.query(lo, hi, tip);
    grid.query_near(near_lo, near_hi, a, b, radius, shaft);
    grid.query_ranks(lo, hi, true, near_lo, near_hi, a, b, radius, ranks);
    std::set<int> expected(tip.begin(), tip.end());
    expected.insert(shaft.begin(), shaft.end());
    ASSERT_EQ(ranks.size(), expected.size()) << "query " << q;
    for (std::size_t k = 0; k < ranks.size(); ++k) {
      if (k > 0) {
        ASSERT_LT(ranks[k - 1], ranks[k]) << "query " << q << ": not ascending";
      }
      ASSERT_TRUE(expected.count(grid.item(ranks[k]))) << "query " << q << ": rank " << ranks[k];
    }
    grid.query_ranks(lo, hi, false, near_lo, near_hi, a, b, radius, alone);
    ASSERT_EQ(alone.size(), tip.size()) << "query " << q;
    for (std::size_t k = 0; k < alone.size(); ++k) ASSERT_EQ(grid.item(alone[k]), tip[k]);
  }
  // A second box wholly beside the grid adds nothing; the first one beside it lists only the
  // second's.
  const Vec3 far(0.5, 0.5, 0.5);
  ranks.clear();
  tip.clear();
  grid.query(Vec3::Constant(-0.01), Vec3::Constant(0.01), tip);
  grid.query_ranks(Vec3::Constant(-0.01), Vec3::Constant(0.01), true, far, far, far, far, 0.001,
                   ranks);
  ASSERT_EQ(ranks.size(), tip.size());
  ranks.clear();
  grid.query_ranks(far, far, true, Vec3::Constant(-0.01), Vec3::Constant(0.01), Vec3::Zero(),
                   Vec3::Zero(), 0.05, ranks);
  ASSERT_EQ(ranks.size(), tip.size());
  EXPECT_THROW(grid.query_ranks(Vec3::Zero(), Vec3::Zero(), true, Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), Vec3::Zero(), -1.0,
                                ranks),
               std::invalid_argument);
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

// The tip's node and edge row normal (exit_normal): radial within the feature's normal cone;
// over a flat surface (cos alpha 1) the sphere's normal where the point, moved along m, leaves
// the sphere, the same for every height of the centre (no switch where the centre crosses the
// surface, and no turn along m); its depth r - n . d the tangent plane's, continuous into the
// gap r - perp where the line misses the sphere; a centre behind the feature pushes along m.
TEST(interaction_tool_geometry, ExitNormalIsTheSpheresWhereThePointLeavesIt) {
  const double r = 0.002;
  const Vec3 m(0, 0, 1);
  // A ridge (cone of 30 degrees): d within 20 degrees of m is radial.
  const Vec3 in_cone = 0.0015 * Vec3(std::sin(0.35), 0, std::cos(0.35));
  EXPECT_TRUE(exit_normal(in_cone, m, std::cos(0.52), r).isApprox(in_cone.normalized(), 1e-12));
  // Flat: the point 1.2 mm beside the axis; the exit point sqrt(r^2 - 1.2^2 mm^2) below the
  // centre along m, at every height of the centre (in front, on, behind the surface).
  const double e = 0.0012, below = std::sqrt(r * r - e * e);
  const Vec3 expect = Vec3(-e, 0, below) / r;
  for (double h : {0.001, 1e-9, 0.0, -1e-9, -0.001}) {
    const Vec3 d(-e, 0, h);
    const Vec3 n = exit_normal(d, m, 1.0, r);
    EXPECT_TRUE(n.isApprox(expect, 1e-12)) << "height " << h;
    // Depth r - n . d: the point moved along m by it (times n . m) lies on the sphere.
    const double depth = r - n.dot(d);
    const double t = depth / n.dot(m);
    EXPECT_NEAR((d + t * m).norm(), r, 1e-15) << "height " << h;
  }
  // Where the line misses the sphere: the direction across to the centre, depth r - perp;
  // at the tangent both ways agree (depth 0, n across).
  const Vec3 beside(-0.003, 0, 0.0005);
  EXPECT_TRUE(exit_normal(beside, m, 1.0, r).isApprox(Vec3(-1, 0, 0), 1e-12));
  const Vec3 tangent_in(-r * (1 - 1e-9), 0, 0.0005), tangent_out(-r * (1 + 1e-9), 0, 0.0005);
  EXPECT_LT((exit_normal(tangent_in, m, 1.0, r) - exit_normal(tangent_out, m, 1.0, r)).norm(), 1e-4);
  // A centre straight behind a ridge's feature: along m.
  EXPECT_TRUE(exit_normal(Vec3(0, 0, -0.0005), m, std::cos(0.52), r).isApprox(m, 1e-12));
}

// exit_normal_turn against central differences of exit_normal (h = 1 nm on a 2 mm sphere: the
// truncation ~h^2 / r^3, the rounding ~1e-16 / h against |J| ~ 1 / r, both under 1e-6 of |J|):
// in a ridge's cone (radial), outside it (the line turning into m), on a flat surface (the line
// m, also with the centre on m, where the degenerate cone has no radial neighbourhood), in front
// of and behind the surface, and where the line misses the sphere. Asserted within 1e-5 of |J|.
TEST(interaction_tool_geometry, ExitNormalTurnIsItsDerivative) {
  const double r = 0.002, h = 1e-9;
  const Vec3 m(0, 0, 1);
  struct Case {
    const char* what;
    Vec3 d;
    double cos_alpha;
  };
  const std::vector<Case> cases = {
      {"ridge, in the cone", 0.0015 * Vec3(std::sin(0.35), 0.1, std::cos(0.35)), std::cos(0.52)},
      {"ridge, outside", 0.0015 * Vec3(std::sin(1.0), 0.3, std::cos(1.0)), std::cos(0.52)},
      {"ridge, outside, behind", Vec3(0.0012, -0.0003, -0.0004), std::cos(0.3)},
      {"flat, beside", Vec3(-0.0012, 0.0004, 0.0005), 1.0},
      {"flat, behind", Vec3(0.0007, 0.0002, -0.0009), 1.0},
      {"flat, on m", Vec3(0, 0, 0.00027), 1.0},
      {"flat, line misses", Vec3(-0.0025, 0.0004, 0.0005), 1.0},
  };
  for (const auto& c : cases) {
    const Eigen::Matrix3d j = exit_normal_turn(c.d, m, c.cos_alpha, r);
    Eigen::Matrix3d fd;
    for (int a = 0; a < 3; ++a) {
      Vec3 e = Vec3::Zero();
      e[a] = h;
      fd.col(a) = (exit_normal(c.d + e, m, c.cos_alpha, r) - exit_normal(c.d - e, m, c.cos_alpha, r)) /
                  (2.0 * h);
    }
    EXPECT_GT(fd.norm(), 0.1 / r) << c.what;
    EXPECT_LE((j - fd).norm(), 1e-5 * fd.norm()) << c.what << "\nJ\n" << j << "\nfd\n" << fd;
  }
}

// capsule_exit (the shaft's exit point): in the feature's cone radial (n = d / |d|, the depth
// r - |d|: the point against a rigid capsule); over a flat surface with the shaft lying on it the
// capsule's normal where the normal line through the point enters it, at every height of the
// axis (in front, on, behind the surface: no switch where the axis crosses the tangent plane);
// past the shaft's end its end sphere's; the line missing the capsule (the direction across,
// depth r - distance) agreeing with the exit at the tangent; a shaft piercing the surface (the
// line along the axis) held to its cross-section's sphere, the depth within 2 r. Against the
// geometry by hand (the exit point on the capsule's surface, on the line).
TEST(interaction_tool_geometry, CapsuleExitIsTheCapsulesWhereThePointLeavesIt) {
  const double r = 0.0005, len = 0.05;
  const Vec3 p0(0, 0, 0), p1(0, len, 0), m(0, 0, 1);
  // In a ridge's cone (30 degrees): radial from the axis point closest to the point.
  const Vec3 x_cone(0.0001, 0.01, -0.0003);
  const CapsuleExit in = capsule_exit(x_cone, p0, p1, m, std::cos(0.52), r);
  const Vec3 d_cone = Vec3(0, 0.01, 0) - x_cone;
  EXPECT_TRUE(in.normal.isApprox(d_cone.normalized(), 1e-12));
  EXPECT_NEAR(r - in.normal.dot(in.centre - x_cone), r - d_cone.norm(), 1e-15);
  // Flat: the point 0.3 mm beside the axis, the line along m enters the cylinder 0.4 mm below
  // the axis: n = (-0.3, 0, 0.4) / 0.5 at every height h of the axis above the point.
  for (double h : {0.0004, 1e-9, 0.0, -1e-9, -0.0003}) {
    const Vec3 x(0.0003, 0.02, -h);
    const CapsuleExit e = capsule_exit(x, p0, p1, m, 1.0, r);
    EXPECT_TRUE(e.normal.isApprox(Vec3(-0.3, 0, 0.4) / 0.5, 1e-12)) << "height " << h;
    EXPECT_TRUE(e.centre.isApprox(Vec3(0, 0.02, 0), 1e-12)) << "height " << h;
    // The depth r - n . (centre - x): the point moved along -m by depth / n . m (into the
    // tissue) is on the capsule.
    const double depth = r - e.normal.dot(e.centre - x);
    const Vec3 on = x - depth / e.normal.dot(m) * m;
    EXPECT_NEAR((on - closest_on_segment(on, p0, p1)).norm(), r, 1e-15) << "height " << h;
  }
  // Beyond the end p1: the line along m enters the end sphere.
  const Vec3 x_end(0.0001, len + 0.0002, -0.0001);
  const CapsuleExit end = capsule_exit(x_end, p0, p1, m, 1.0, r);
  EXPECT_TRUE(end.centre.isApprox(p1, 1e-15));
  EXPECT_NEAR((x_end - (r - end.normal.dot(end.centre - x_end)) / end.normal.dot(m) * m - p1).norm(),
              r, 1e-15);
  // Missing: the line along m 0.7 mm beside the axis; across to it, the depth -0.2 mm; at the
  // tangent both ways agree.
  const CapsuleExit miss = capsule_exit(Vec3(0.0007, 0.02, 0.0001), p0, p1, m, 1.0, r);
  EXPECT_TRUE(miss.normal.isApprox(Vec3(-1, 0, 0), 1e-12));
  EXPECT_NEAR(r - miss.normal.dot(miss.centre - Vec3(0.0007, 0.02, 0.0001)), -0.0002, 1e-15);
  const Vec3 t_in(r * (1 - 1e-9), 0.02, 0.0001), t_out(r * (1 + 1e-9), 0.02, 0.0001);
  EXPECT_LT((capsule_exit(t_in, p0, p1, m, 1.0, r).normal - capsule_exit(t_out, p0, p1, m, 1.0, r).normal)
                .norm(),
            1e-4);
  // Piercing: the axis along the surface's normal y, the point 0.3 mm off the axis 20 mm up it:
  // the cross-section's sphere, n = (-0.3, 0.4, 0) / 0.5 where the point moved 0.4 mm down the
  // line leaves it, depth n . m 0.4 mm = 0.32 mm (the ray along the axis would leave the capsule
  // only past p0, 20 mm down).
  const Vec3 x_pierce(0.0003, 0.02, 0.0);
  const CapsuleExit pierce = capsule_exit(x_pierce, p0, p1, Vec3(0, 1, 0), 1.0, r);
  EXPECT_TRUE(pierce.normal.isApprox(Vec3(-0.3, 0.4, 0) / 0.5, 1e-12));
  EXPECT_NEAR(r - pierce.normal.dot(pierce.centre - x_pierce), 0.00032, 1e-15);
}

// capsule_exit's dn_dx against central differences of its normal in the point x (h = 0.1 nm on
// a 0.5 mm capsule: truncation ~h^2 / r^3, rounding ~1e-16 / h against |J| ~ 1 / r): radial in a
// ridge's cone (the axis point sliding with x), outside it, on a flat surface beside the axis in
// front of and behind it, past the shaft's end (its end sphere, the centre fixed), a tilted
// surface, and the line missing the capsule beside it and past its end. Asserted within 1e-5 of
// |J|.
TEST(interaction_tool_geometry, CapsuleExitTurnIsItsDerivative) {
  const double r = 0.0005, len = 0.05, h = 1e-10;
  const Vec3 p0(0, 0, 0), p1(0, len, 0);
  struct Case {
    const char* what;
    Vec3 x;
    Vec3 m;
    double cos_alpha;
  };
  const Vec3 z(0, 0, 1);
  const std::vector<Case> cases = {
      {"ridge, in the cone", Vec3(0.0001, 0.01, -0.0003), z, std::cos(0.52)},
      {"ridge, outside", Vec3(0.0003, 0.01, -0.0001), z, std::cos(0.52)},
      {"ridge, outside, behind", Vec3(0.0002, 0.01, 0.0001), z, std::cos(0.3)},
      {"flat, in front", Vec3(0.0003, 0.02, -0.0002), z, 1.0},
      {"flat, behind", Vec3(0.0002, 0.02, 0.0001), z, 1.0},
      {"flat, end sphere", Vec3(0.0001, len + 0.0002, -0.0001), z, 1.0},
      {"tilted surface", Vec3(0.0002, 0.03, -0.0002), Vec3(0.3, 0.4, 1).normalized(), 1.0},
      {"ridge, tilted, end", Vec3(0.0001, len + 0.0001, -0.0002), Vec3(0.2, 0.5, 1).normalized(),
       std::cos(0.4)},
      {"missing beside", Vec3(0.0007, 0.02, 0.0001), z, std::cos(0.3)},
      {"missing past the end", Vec3(0.0003, len + 0.0007, 0.0001), z, 1.0},
  };
  for (const auto& c : cases) {
    Eigen::Matrix3d j;
    capsule_exit(c.x, p0, p1, c.m, c.cos_alpha, r, &j);
    Eigen::Matrix3d fd;
    for (int a = 0; a < 3; ++a) {
      Vec3 e = Vec3::Zero();
      e[a] = h;
      fd.col(a) = (capsule_exit(c.x + e, p0, p1, c.m, c.cos_alpha, r).normal -
                   capsule_exit(c.x - e, p0, p1, c.m, c.cos_alpha, r).normal) /
                  (2.0 * h);
    }
    EXPECT_GT(fd.norm(), 0.05 / r) << c.what;
    EXPECT_LE((j - fd).norm(), 1e-5 * fd.norm()) << c.what << "\nJ\n" << j << "\nfd\n" << fd;
    std::printf("%s: |J| %.1f 1/m, off %.1e\n", c.what, fd.norm(), (j - fd).norm() / fd.norm());
  }
}

TEST(interaction_tool_geometry, ClosestPointOfASegmentIsClampedToItsEnds) {
  const Vec3 p0(0, 0, 0), p1(1, 0, 0);
  EXPECT_TRUE(closest_on_segment(Vec3(0.3, 2, 0), p0, p1).isApprox(Vec3(0.3, 0, 0)));
  EXPECT_TRUE(closest_on_segment(Vec3(-1, 1, 0), p0, p1).isApprox(p0));
  EXPECT_TRUE(closest_on_segment(Vec3(3, -1, 0), p0, p1).isApprox(p1));
  EXPECT_TRUE(closest_on_segment(Vec3(3, -1, 0), p0, p0).isApprox(p0)) << "a point segment";
}

// The patch near field (SimulationOptions::contact_near_field) on a circle is the tip's
// formula (contact_step.cpp near_field_of_tool): (0.75 / a - 0.766 / sqrt(rho^2 + q a^2)) / E*.
TEST(interaction_tool_geometry, PatchNearFieldOnACircleIsTheTips) {
  const double e_star = 3000.0 / (1.0 - 0.49 * 0.49);
  constexpr double kQ = (0.766 / 0.75) * (0.766 / 0.75);
  for (double a : {0.5e-3, 1e-3, 2e-3, 4e-3})
    for (double rho : {0.5e-3, 2e-3, 4e-3, 8e-3}) {
      const double tip =
          std::max(0.0, (0.75 / a - 0.766 / std::sqrt(rho * rho + kQ * a * a)) / e_star);
      EXPECT_NEAR(patch_near_field(a, a, rho, e_star), tip, 1e-12 * (0.75 / a / e_star))
          << "a " << a << " rho " << rho;
    }
}

// Against Hertz's elliptic contact (Johnson, Contact Mechanics, 4.2): with a spread far wider
// than the patch the near field is the patch's own secant compliance 3 K(e) / (2 pi a E*), K
// here by quadrature of its integral (not the AGM of the source), e^2 = 1 - b^2 / a^2, either
// order of the semi-axes; and a long patch's is the finite line contact's 3 ln(4 a / b) /
// (2 pi a E*).
TEST(interaction_tool_geometry, PatchNearFieldIsHertzsEllipticCompliance) {
  const double e_star = 4000.0;
  auto k_quadrature = [](double k) {  // composite Simpson over [0, pi / 2]
    const int n = 200000;
    const double h = 0.5 * M_PI / n;
    double sum = 0.0;
    for (int i = 0; i <= n; ++i) {
      const double s = std::sin(i * h);
      const double f = 1.0 / std::sqrt(1.0 - k * k * s * s);
      sum += (i == 0 || i == n ? 1.0 : (i % 2 ? 4.0 : 2.0)) * f;
    }
    return sum * h / 3.0;
  };
  const double a = 3e-3;
  for (double ratio : {1.0, 0.7, 0.3, 0.1, 0.02}) {
    const double b = ratio * a;
    const double k = std::sqrt(1.0 - ratio * ratio);
    const double hertz = 3.0 * k_quadrature(k) / (2.0 * M_PI * a * e_star);
    EXPECT_NEAR(patch_near_field(a, b, 1e6, e_star), hertz, 1e-7 * hertz) << "b / a " << ratio;
    EXPECT_NEAR(patch_near_field(b, a, 1e6, e_star), hertz, 1e-7 * hertz) << "b / a " << ratio;
  }
  const double b = 1e-4 * a;
  const double line = 3.0 * std::log(4.0 * a / b) / (2.0 * M_PI * a * e_star);
  EXPECT_NEAR(patch_near_field(a, b, 1e6, e_star), line, 1e-6 * line);
}

// The mesh resolves a patch wider than its spread: the near field vanishes as rho -> 0 (none
// at rho = 0) and grows with the spread.
TEST(interaction_tool_geometry, PatchNearFieldVanishesAsTheSpreadShrinks) {
  const double e_star = 4000.0, a = 3e-3, b = 1.5e-3;
  EXPECT_EQ(patch_near_field(a, b, 0.0, e_star), 0.0);
  const double at_a = patch_near_field(a, b, a, e_star);
  EXPECT_GT(at_a, 0.0);
  EXPECT_LT(patch_near_field(a, b, 1e-3 * a, e_star), 1e-5 * at_a);
  double last = 0.0;
  for (double rho = 0.1e-3; rho < 20e-3; rho *= 1.5) {
    const double c = patch_near_field(a, b, rho, e_star);
    EXPECT_GT(c, last) << "rho " << rho;
    last = c;
  }
}

// The shaft's patch (tool_geometry.hpp shaft_patch): across the axis Hertz's sqrt(R d) with the
// capsule's radius, at most the radius; along it the wedge d / (pi tan theta), between the
// across semi-axis and half the shaft's length.
TEST(interaction_tool_geometry, ShaftPatchIsTheCapsulesWedge) {
  const double rs = 1.5e-3, ls = 0.05;
  double a = 0.0, b = 0.0;
  shaft_patch(1e-3, 0.1, rs, ls, a, b);
  EXPECT_NEAR(b, std::sqrt(rs * 1e-3), 1e-15);
  EXPECT_NEAR(a, 1e-3 * std::sqrt(1.0 - 0.1 * 0.1) / (M_PI * 0.1), 1e-15);
  shaft_patch(1e-3, 0.5, rs, ls, a, b);
  EXPECT_NEAR(a, b, 1e-15) << "a wedge shorter than the capsule is wide: its round end";
  shaft_patch(3e-3, 0.256, rs, ls, a, b);
  EXPECT_NEAR(b, rs, 1e-15) << "deeper than the radius";
  shaft_patch(1e-3, 0.0, rs, ls, a, b);
  EXPECT_NEAR(a, 0.5 * ls, 1e-15) << "lying on the surface";
  shaft_patch(1e-3, 1e-9, rs, ls, a, b);
  EXPECT_NEAR(a, 0.5 * ls, 1e-15);
  shaft_patch(1e-3, 1.0, rs, ls, a, b);
  EXPECT_NEAR(a, b, 1e-15) << "along the normal: the round end";
}

}  // namespace
}  // namespace neurosim::interaction
