// surface_probe: the top of a box's surface on a vertical line and the closest surface point to
// points above, beside and inside a box (the answers are the box's faces, known exactly), the
// point at a distance from the box along an axis; the
// top of a rigid box obstacle, and a ring of two boxes whose centre line misses it.
#include "server/interaction/surface_probe.hpp"

#include "server/fem/fem_test_meshes.hpp"
#include "server/interaction/rigid_obstacle.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

namespace neurosim::interaction {
namespace {

using mesh::Vec3;

mesh::TetMesh box() {
  fem::testing::BoxSpec s;
  s.nx = 4;
  s.ny = 3;
  s.nz = 2;
  s.lo = Vec3(0.0, 0.0, 0.0);
  s.hi = Vec3(0.04, 0.03, 0.02);  // unit m
  return fem::testing::box_mesh(s);
}

TEST(interaction_surface_probe, TopOfABoxIsItsUpperFace) {
  const mesh::TetMesh m = box();
  // Inside a triangle, on an edge of the grid and on a vertex of the upper face.
  for (const Vec3& xy : {Vec3(0.013, 0.017, 0), Vec3(0.02, 0.015, 0), Vec3(0.01, 0.01, 0)}) {
    const auto top = top_of_surface(m, xy.x(), xy.y());
    ASSERT_TRUE(top.has_value());
    EXPECT_NEAR(top->point_m.z(), 0.02, 1e-15);
    EXPECT_NEAR(top->point_m.x(), xy.x(), 1e-15);
    EXPECT_NEAR(top->point_m.y(), xy.y(), 1e-15);
    EXPECT_NEAR(top->normal.z(), 1.0, 1e-12);
  }
  EXPECT_FALSE(top_of_surface(m, 0.05, 0.01).has_value());  // beside the box
  EXPECT_THROW(top_of_surface(m, std::nan(""), 0.01), std::invalid_argument);
}

TEST(interaction_surface_probe, ClosestPointAboveBesideAndInside) {
  const mesh::TetMesh m = box();
  SurfacePoint p = closest_on_surface(m, Vec3(0.011, 0.012, 0.025));  // above the upper face
  EXPECT_LT((p.point_m - Vec3(0.011, 0.012, 0.02)).norm(), 1e-15);
  EXPECT_NEAR(p.normal.z(), 1.0, 1e-12);
  p = closest_on_surface(m, Vec3(0.045, 0.012, 0.01));  // beside the x = 0.04 face
  EXPECT_LT((p.point_m - Vec3(0.04, 0.012, 0.01)).norm(), 1e-15);
  EXPECT_NEAR(p.normal.x(), 1.0, 1e-12);
  p = closest_on_surface(m, Vec3(0.02, 0.015, 0.018));  // inside, 2 mm under the upper face
  EXPECT_LT((p.point_m - Vec3(0.02, 0.015, 0.02)).norm(), 1e-15);
  p = closest_on_surface(m, Vec3(0.05, 0.04, 0.03));  // outside the corner (0.04, 0.03, 0.02)
  EXPECT_LT((p.point_m - Vec3(0.04, 0.03, 0.02)).norm(), 1e-15);
  EXPECT_THROW(closest_on_surface(m, Vec3(0, std::nan(""), 0)), std::invalid_argument);
  EXPECT_THROW(closest_on_surface(mesh::TetMesh{}, Vec3::Zero()), std::invalid_argument);
}

// The tip placement of the contact slide: from a point of the upper face along a tilted axis
// (30 degrees from the face's normal) the point 1 mm from the face is t = 1 mm / cos 30 out; along
// an axis into the box the first point 1 mm from the surface is 1 mm below the bottom face (the
// line inside the box is behind the surface), none within a shorter reach; distance 0 is the
// surface point itself, whichever way the axis points.
TEST(interaction_surface_probe, PointAtADistanceAlongAnAxis) {
  const mesh::TetMesh m = box();
  const Vec3 at(0.02, 0.015, 0.02);
  const Vec3 tilted = Vec3(0.5, 0.0, std::sqrt(0.75));
  auto x = at_distance_along(m, at, tilted, 1e-3);
  ASSERT_TRUE(x.has_value());
  EXPECT_LT((*x - (at + (1e-3 / std::sqrt(0.75)) * tilted)).norm(), 1e-9);
  const Vec3 down(0.0, 0.0, -1.0);
  x = at_distance_along(m, at, down, 1e-3);
  ASSERT_TRUE(x.has_value());
  EXPECT_LT((*x - Vec3(0.02, 0.015, -0.001)).norm(), 1e-9);
  EXPECT_FALSE(at_distance_along(m, at, down, 1e-3, 0.01).has_value());
  for (const Vec3& axis : {tilted, down}) {
    x = at_distance_along(m, at, axis, 0.0);
    ASSERT_TRUE(x.has_value());
    EXPECT_LT((*x - at).norm(), 1e-9);
  }
  EXPECT_THROW(at_distance_along(m, at, Vec3(0, 0, 2), 1e-3), std::invalid_argument);
  EXPECT_THROW(at_distance_along(m, at, down, -1e-3), std::invalid_argument);
}

// The box's surface triangles as a rigid obstacle.
scene::RigidSurface rigid(const mesh::TetMesh& m, const Vec3& shift = Vec3::Zero()) {
  scene::RigidSurface r;
  r.id = "box";
  for (const Vec3& v : m.vertices()) r.vertices_m.push_back(v + shift);
  r.triangles = m.surface();
  return r;
}

TEST(interaction_surface_probe, TopOfARigidObstacleIsWhereTheCentreLineEntersIt) {
  const mesh::TetMesh m = box();
  const auto obstacle = RigidObstacle::build({rigid(m)});
  ASSERT_NE(obstacle, nullptr);
  const Vec3 top = top_of_obstacle(*obstacle);
  EXPECT_EQ(top.x(), 0.02);
  EXPECT_EQ(top.y(), 0.015);
  EXPECT_LE(top.z(), 0.02);  // inside, within one step of the upper face
  EXPECT_GT(top.z(), 0.02 - 5e-5);
  EXPECT_TRUE(obstacle->inside(top));
  const Vec3 fine = top_of_obstacle(*obstacle, 1e-6);
  EXPECT_GT(fine.z(), 0.02 - 1e-6);
  EXPECT_THROW(top_of_obstacle(*obstacle, 0.0), std::invalid_argument);
  EXPECT_THROW(top_of_obstacle(*obstacle, std::nan("")), std::invalid_argument);
  // Two boxes 20 mm apart: the line through the middle of their bounding box misses both.
  const auto pair = RigidObstacle::build({rigid(m), rigid(m, Vec3(0.06, 0.0, 0.0))});
  EXPECT_THROW(top_of_obstacle(*pair), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
