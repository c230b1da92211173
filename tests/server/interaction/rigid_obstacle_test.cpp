// RigidObstacle on the skull of scenes/brain_skull.scene: the BVH's closest points against brute
// force over all 7538 triangles, the planes of a query against brute force, normals facing the
// free side, and nothing built for a scene without rigid meshes.
#include "server/interaction/rigid_obstacle.hpp"

#include "rigid_fixtures.hpp"
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/triangle_bvh.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace neurosim::interaction {
namespace {

using testing::skull;

double brute_distance(const RigidObstacle& o, const mesh::Vec3& p, int* tri = nullptr) {
  double best = std::numeric_limits<double>::infinity();
  for (int t = 0; t < o.num_triangles(); ++t) {
    const auto& f = o.triangles()[static_cast<std::size_t>(t)];
    const auto& v = o.vertices_m();
    const double d = (fusion::closest_point_on_triangle(p, v[f[0]], v[f[1]], v[f[2]]).point_m - p).norm();
    if (d < best) {
      best = d;
      if (tri) *tri = t;
    }
  }
  return best;
}

TEST(interaction_rigid_obstacle, NoRigidSurfaceBuildsNothing) {
  EXPECT_EQ(RigidObstacle::build({}), nullptr);
  const scene::Model cube = scene::load_model(std::filesystem::path(NEUROSIM_SOURCE_DIR) /
                                              "scenes/cube_cylinder.scene");
  ASSERT_TRUE(cube.rigid.empty());
  EXPECT_EQ(RigidObstacle::build(cube.rigid), nullptr);
}

TEST(interaction_rigid_obstacle, SkullIsClosedAndOutward) {
  const RigidObstacle& o = skull();
  EXPECT_EQ(o.num_triangles(), 7538);  // scenes/brain_skull/skull.mesh
  // Far outside: winding 0; just behind a face (inside the bone): 1.
  EXPECT_NEAR(o.winding_number(mesh::Vec3(1.0, 1.0, 1.0)), 0.0, 1e-9);
  const auto& f = o.triangles()[100];
  const mesh::Vec3 c = (o.vertices_m()[f[0]] + o.vertices_m()[f[1]] + o.vertices_m()[f[2]]) / 3.0;
  EXPECT_NEAR(o.winding_number(c - 1e-4 * o.face_normal(100)), 1.0, 1e-6);
  EXPECT_NEAR(o.winding_number(c + 1e-4 * o.face_normal(100)), 0.0, 1e-6);
}

TEST(interaction_rigid_obstacle, ClosestPointEqualsBruteForce) {
  const RigidObstacle& o = skull();
  mesh::Vec3 lo = o.vertices_m().front(), hi = lo;
  for (const auto& v : o.vertices_m()) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (int k = 0; k < 200; ++k) {
    const mesh::Vec3 p = lo + (hi - lo).cwiseProduct(mesh::Vec3(u(rng), u(rng), u(rng)));
    const double brute = brute_distance(o, p);
    const auto c = o.closest(p);
    EXPECT_NEAR(c.distance_m, brute, 1e-12) << "point " << k;
    EXPECT_NEAR((c.point_m - p).norm(), brute, 1e-12);
  }
}

// Free tip points near the surface (outside the bone): the nearest plane is the brute-force
// closest point, moved out by the tip radius, facing the tip; every plane is a closest point of
// its triangle; nothing penetrates at the free pose.
TEST(interaction_rigid_obstacle, TipPlanesEqualBruteForce) {
  const RigidObstacle& o = skull();
  auto scratch = o.make_scratch();
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> pick(0, o.num_triangles() - 1);
  std::uniform_real_distribution<double> off(0.0025, 0.006);
  ToolShape tip{0.002, 0.0, 0.0};  // tip only: shaft planes are checked by the proxy tests
  int checked = 0;
  for (int k = 0; k < 200 && checked < 60; ++k) {
    const int t = pick(rng);
    const auto& f = o.triangles()[static_cast<std::size_t>(t)];
    const mesh::Vec3 c = (o.vertices_m()[f[0]] + o.vertices_m()[f[1]] + o.vertices_m()[f[2]]) / 3.0;
    const mesh::Vec3 x = c + off(rng) * o.face_normal(t);
    if (o.inside(x)) continue;
    const double d = brute_distance(o, x);
    if (d < tip.tip_radius_m) continue;  // the tip sphere would touch another part of the shell
    ObstacleQuery q;
    q.free_known = true;
    q.free_tip_m = x;
    q.tip_m = x;
    q.shape = tip;
    q.reach_m = 0.005;
    ObstaclePlanes planes;
    o.query(q, scratch, planes);
    ASSERT_GE(planes.count, 1) << "point " << k;
    const auto& p0 = planes.planes[0];
    EXPECT_NEAR(p0.normal.norm(), 1.0, 1e-12);
    EXPECT_NEAR(p0.normal.dot(x - p0.point_m), d - tip.tip_radius_m, 1e-10) << "point " << k;
    EXPECT_NEAR((p0.surface_point_m - x).norm(), d, 1e-10);
    for (int i = 0; i < planes.count; ++i) {
      const auto& p = planes.planes[static_cast<std::size_t>(i)];
      EXPECT_EQ(p.penetration_m, 0.0);
      EXPECT_GE(p.normal.dot(x - p.point_m), -1e-12);
      const auto& g = o.triangles()[static_cast<std::size_t>(p.triangle)];
      EXPECT_NEAR((fusion::closest_point_on_triangle(x, o.vertices_m()[g[0]], o.vertices_m()[g[1]],
                                                     o.vertices_m()[g[2]]).point_m -
                   p.surface_point_m).norm(), 0.0, 1e-12);
      for (int j = 0; j < i; ++j)
        EXPECT_LT(p.normal.dot(planes.planes[static_cast<std::size_t>(j)].normal), 0.985);
    }
    ++checked;
  }
  EXPECT_GE(checked, 30);
}

// Far from the bone (beyond the reach): no plane.
TEST(interaction_rigid_obstacle, NoPlaneBeyondReach) {
  const RigidObstacle& o = skull();
  auto scratch = o.make_scratch();
  ObstacleQuery q;
  q.free_known = true;
  q.free_tip_m = q.tip_m = mesh::Vec3(1.0, 1.0, 1.0);
  q.shape = testing::probe_shape();
  ObstaclePlanes planes;
  o.query(q, scratch, planes);
  EXPECT_EQ(planes.count, 0);
}

}  // namespace
}  // namespace neurosim::interaction
