// Closed triangle surfaces (rigid obstacles): check_closed counts every kind of defect and names
// the first; the enclosed volume by the divergence theorem is exact for a box wherever it lies;
// require_closed_outward refuses an open, inconsistent or inward surface naming the source.
#include "server/mesh/tri_surface.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

namespace neurosim::mesh {
namespace {

using neurosim::testing::contains;
using neurosim::testing::message_of;

// A box [lo, hi] as 12 outward triangles.
void box(const Vec3& lo, const Vec3& hi, std::vector<Vec3>& x, std::vector<Tri>& t) {
  x.clear();
  for (int k = 0; k < 8; ++k)
    x.emplace_back(k & 1 ? hi.x() : lo.x(), k & 2 ? hi.y() : lo.y(), k & 4 ? hi.z() : lo.z());
  // Each face as two triangles, counter-clockwise seen from outside.
  t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
       {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
}

TEST(TriSurface, ClosedCheckCountsEveryDefect) {
  const std::vector<Vec3> x{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  const std::vector<Tri> closed{{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  auto r = check_closed(x, closed);
  EXPECT_TRUE(r.closed());
  EXPECT_EQ(r.edges, 6);
  EXPECT_NEAR(r.volume_m3, 1.0 / 6.0, 1e-15);
  EXPECT_EQ(r.first_problem, "");
  auto open = closed;
  open.pop_back();
  r = check_closed(x, open);
  EXPECT_FALSE(r.closed());
  EXPECT_EQ(r.boundary_edges, 3);
  EXPECT_PRED2(contains, r.first_problem, "is on a hole (1 triangle)");
  auto flipped = closed;
  std::swap(flipped[3][1], flipped[3][2]);
  r = check_closed(x, flipped);
  EXPECT_EQ(r.misoriented_edges, 3);
  EXPECT_PRED2(contains, r.first_problem, "inconsistent orientation");
  auto extra = closed;
  extra.push_back({1, 2, 3});
  r = check_closed(x, extra);
  EXPECT_EQ(r.nonmanifold_edges, 3);
  EXPECT_PRED2(contains, r.first_problem, "non-manifold (3 triangles)");
  // A repeated vertex and an index out of range: counted, left out of the edges, named.
  auto degenerate = closed;
  degenerate.push_back({0, 0, 1});
  degenerate.push_back({0, 1, 4});
  r = check_closed(x, degenerate);
  EXPECT_EQ(r.degenerate_triangles, 2);
  EXPECT_EQ(r.edges, 6);
  EXPECT_FALSE(r.closed());
  EXPECT_EQ(r.first_problem, "triangle 4 repeats a vertex or indexes none");
  EXPECT_FALSE(check_closed(x, {}).closed()) << "no triangles is not a closed surface";
}

// The divergence theorem's volume does not depend on where the box lies (the origin term cancels
// on a closed surface); reversed, it is the negative.
TEST(TriSurface, BoxVolumeIsExactAnywhere) {
  std::vector<Vec3> x;
  std::vector<Tri> t;
  for (const Vec3& lo : {Vec3(0, 0, 0), Vec3(-0.3, 0.2, 0.1), Vec3(5.0, -7.0, 11.0)}) {
    box(lo, lo + Vec3(0.2, 0.15, 0.1), x, t);
    const ClosedSurfaceReport r = check_closed(x, t);
    EXPECT_TRUE(r.closed()) << r.first_problem;
    EXPECT_EQ(r.edges, 18);
    EXPECT_NEAR(r.volume_m3, 0.2 * 0.15 * 0.1, 1e-12) << lo.transpose();
    EXPECT_NO_THROW(require_closed_outward(x, t, "box.mesh"));
    for (auto& f : t) std::swap(f[1], f[2]);
    EXPECT_NEAR(check_closed(x, t).volume_m3, -0.2 * 0.15 * 0.1, 1e-12);
  }
}

TEST(TriSurface, RequireClosedOutwardNamesTheSourceAndTheDefect) {
  std::vector<Vec3> x;
  std::vector<Tri> t;
  box(Vec3(0, 0, 0), Vec3(1, 1, 1), x, t);
  auto inward = t;
  for (auto& f : inward) std::swap(f[1], f[2]);
  std::string e = message_of([&] { require_closed_outward(x, inward, "skull.mesh"); });
  EXPECT_PRED2(contains, e, "skull.mesh: closed surface with enclosed volume -1 m^3 <= 0");
  EXPECT_PRED2(contains, e, "face inward");
  auto open = t;
  open.pop_back();
  e = message_of([&] { require_closed_outward(x, open, "skull.mesh"); });
  EXPECT_PRED2(contains, e, "skull.mesh: not a closed, consistently oriented surface: 3 boundary");
  EXPECT_PRED2(contains, e, "first: edge (");
  EXPECT_EQ(message_of([&] { require_closed_outward(x, {}, "empty.mesh"); }),
            "empty.mesh: not a closed surface: no triangles");
}

}  // namespace
}  // namespace neurosim::mesh
