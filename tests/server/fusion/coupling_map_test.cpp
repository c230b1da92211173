// Coupling map: closest points both ways between S' and B's surface, checked against a
// plain search over every triangle.
#include "server/fusion/coupling_map.hpp"

#include "fusion_fixtures.hpp"

#include <gtest/gtest.h>

#include <random>

namespace neurosim::fusion {
namespace {

using test::structured_box;

TEST(fusion_coupling_map, ClosestPointOnTriangleRegions) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0, 1, 0);
  struct Case {
    Vec3 p;
    Vec3 q;
  };
  const Case cases[] = {{Vec3(0.2, 0.2, 0.5), Vec3(0.2, 0.2, 0)},  // face
                        {Vec3(-1, -1, 0.3), a},                    // vertex a
                        {Vec3(2, -0.5, 0), b},                     // vertex b
                        {Vec3(-0.2, 3, -1), c},                    // vertex c
                        {Vec3(0.5, -1, 0), Vec3(0.5, 0, 0)},       // edge ab
                        {Vec3(1, 1, 2), Vec3(0.5, 0.5, 0)},        // edge bc
                        {Vec3(-1, 0.25, 0), Vec3(0, 0.25, 0)}};    // edge ca
  for (const auto& k : cases) {
    const SurfacePoint s = closest_point_on_triangle(k.p, a, b, c);
    EXPECT_NEAR((s.point_m - k.q).norm(), 0.0, 1e-14) << k.p.transpose();
    EXPECT_NEAR(s.weights[0] + s.weights[1] + s.weights[2], 1.0, 1e-14);
    EXPECT_NEAR((s.weights[0] * a + s.weights[1] * b + s.weights[2] * c - s.point_m).norm(), 0,
                1e-14);
    EXPECT_NEAR(s.distance_m, (k.p - k.q).norm(), 1e-14);
  }
}

TEST(fusion_coupling_map, BothDirectionsMatchExhaustiveSearch) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 6, 6, 6);
  std::mt19937 rng(3);
  const auto b_mesh = test::transformed(structured_box(Vec3(-1, -1, -1), Vec3(1, 1, 1), 2, 2, 2),
                                        test::random_rotation(rng), 0.2, Vec3(0.5, 0.45, 0.52));
  const auto b = TriangleSurface::of(b_mesh);
  const NewBoundary s = find_new_boundary(a, b);
  ASSERT_FALSE(s.triangles.empty());
  const CouplingMap m = build_coupling_map(a.vertices(), s, b);
  ASSERT_EQ(m.embedded_nodes, b_mesh.surface_vertices());
  ASSERT_EQ(m.boundary_nodes, s.vertices());
  ASSERT_EQ(m.embedded_on_boundary.size(), m.embedded_nodes.size());
  ASSERT_EQ(m.boundary_on_embedded.size(), m.boundary_nodes.size());
  auto exhaustive = [](const Vec3& p, const std::vector<Vec3>& x,
                       const std::vector<mesh::Tri>& tris) {
    double best = 1e300;
    for (const auto& t : tris)
      best = std::min(best, closest_point_on_triangle(p, x[t[0]], x[t[1]], x[t[2]]).distance_m);
    return best;
  };
  double max_d = 0, sum = 0;
  for (std::size_t i = 0; i < m.embedded_nodes.size(); ++i) {
    const Vec3& p = b.vertices_m[m.embedded_nodes[i]];
    const SurfacePoint& sp = m.embedded_on_boundary[i];
    ASSERT_GE(sp.triangle, 0);
    const auto& t = s.triangles[sp.triangle];
    const Vec3 q = sp.weights[0] * a.vertices()[t[0]] + sp.weights[1] * a.vertices()[t[1]] +
                   sp.weights[2] * a.vertices()[t[2]];
    EXPECT_NEAR((q - sp.point_m).norm(), 0.0, 1e-12);
    EXPECT_NEAR((p - q).norm(), sp.distance_m, 1e-12);
    EXPECT_NEAR(sp.distance_m, exhaustive(p, a.vertices(), s.triangles), 1e-12);
    for (double w : sp.weights) EXPECT_GE(w, -1e-12);
    max_d = std::max(max_d, sp.distance_m);
    sum += sp.distance_m;
  }
  EXPECT_DOUBLE_EQ(m.embedded_to_boundary.max_m, max_d);
  EXPECT_NEAR(m.embedded_to_boundary.mean_m, sum / m.embedded_nodes.size(), 1e-15);
  for (std::size_t i = 0; i < m.boundary_nodes.size(); ++i) {
    const Vec3& p = a.vertices()[m.boundary_nodes[i]];
    EXPECT_NEAR(m.boundary_on_embedded[i].distance_m, exhaustive(p, b.vertices_m, b.triangles),
                1e-12);
    EXPECT_GT(m.boundary_on_embedded[i].distance_m, 0.0);  // S' never touches B
  }
  // S' lies within a couple of host cells (h = 1/6 m) of B and vice versa.
  EXPECT_LT(m.embedded_to_boundary.max_m, std::sqrt(3.0) / 6.0);
  EXPECT_LT(m.boundary_to_embedded.max_m, 2 * std::sqrt(3.0) / 6.0);
}

TEST(fusion_coupling_map, EmptyBoundaryIsAnError) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 2, 2, 2);
  const auto b = TriangleSurface::of(structured_box(Vec3(3, 3, 3), Vec3(4, 4, 4), 1, 1, 1));
  EXPECT_THROW(build_coupling_map(a.vertices(), NewBoundary{}, b), std::invalid_argument);
  NewBoundary bad;
  bad.triangles.push_back({0, 1, 1000});
  EXPECT_THROW(build_coupling_map(a.vertices(), bad, b), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
