// ContactSurface and closest_on_triangle: the closest point against a dense sampling of the
// triangle (brute force), its feature and weights; the contactable triangles and edge incidence
// of a box's surface.
#include "server/interaction/contact_surface.hpp"

#include "server/fem/fem_test_meshes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

namespace neurosim::interaction {
namespace {

using mesh::Vec3;

TEST(interaction_contact_surface, ClosestPointMatchesBruteForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const std::array<Vec3, 3> p{Vec3(u(rng), u(rng), u(rng)), Vec3(u(rng), u(rng), u(rng)),
                                Vec3(u(rng), u(rng), u(rng))};
    const Vec3 x = 2.0 * Vec3(u(rng), u(rng), u(rng));
    const TrianglePoint at = closest_on_triangle(x, p);
    // The weights reproduce the point and sum to 1, none negative.
    const Vec3 from_w = at.weights[0] * p[0] + at.weights[1] * p[1] + at.weights[2] * p[2];
    EXPECT_LT((from_w - at.point_m).norm(), 1e-12);
    EXPECT_NEAR(at.weights[0] + at.weights[1] + at.weights[2], 1.0, 1e-12);
    for (double w : at.weights) EXPECT_GE(w, -1e-12);
    // No sample of the triangle is closer.
    double best = std::numeric_limits<double>::infinity();
    const int n = 200;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const double a = double(i) / n, b = double(j) / n;
        best = std::min(best, (x - (p[0] + a * (p[1] - p[0]) + b * (p[2] - p[0]))).norm());
      }
    const double d = (x - at.point_m).norm();
    EXPECT_LE(d, best + 1e-12) << trial;
    EXPECT_GT(d, best - 2e-2) << trial;  // sampling resolution
    // The feature matches the weights: a vertex has one non-zero weight, an edge two.
    const int nonzero = static_cast<int>(
        std::count_if(at.weights.begin(), at.weights.end(), [](double w) { return w > 0.0; }));
    if (at.feature == TriangleFeature::kVertex) {
      EXPECT_EQ(nonzero, 1);
    }
    if (at.feature == TriangleFeature::kEdge) {
      EXPECT_LE(nonzero, 2);
      EXPECT_EQ(at.weights[(at.a + 2) % 3], 0.0);
    }
  }
}

TEST(interaction_contact_surface, FeaturesOfAPointAboveAVertexAnEdgeAFace) {
  const std::array<Vec3, 3> p{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  EXPECT_EQ(closest_on_triangle(Vec3(-0.1, -0.1, 1), p).feature, TriangleFeature::kVertex);
  const TrianglePoint e = closest_on_triangle(Vec3(0.5, -0.2, 1), p);
  EXPECT_EQ(e.feature, TriangleFeature::kEdge);
  EXPECT_EQ(e.a, 0);
  EXPECT_NEAR(e.weights[0], 0.5, 1e-12);
  const TrianglePoint f = closest_on_triangle(Vec3(0.2, 0.2, 1), p);
  EXPECT_EQ(f.feature, TriangleFeature::kFace);
  EXPECT_LT((f.point_m - Vec3(0.2, 0.2, 0)).norm(), 1e-12);
}

TEST(interaction_contact_surface, BoxSurfaceTrianglesAndEdgeIncidence) {
  fem::testing::BoxSpec spec{3, 3, 3};
  const mesh::TetMesh box = fem::testing::box_mesh(spec);
  // Every surface node but the bottom (z = 0, fixed) is a contact slot.
  std::vector<int> slot(box.num_vertices(), -1), fixed;
  int slots = 0;
  for (int v : box.surface_vertices()) {
    if (box.vertices()[v].z() < 1e-9) {
      fixed.push_back(v);
    } else {
      slot[v] = slots++;
    }
  }
  const ContactSurface s(ContactSurfaceDefinition{&box, &slot, &fixed});
  // 6 faces x 9 quads x 2 triangles; the bottom face has only fixed nodes: not contactable.
  EXPECT_EQ(s.triangles().size(), 5u * 18u);
  for (const auto& t : s.triangles()) {
    for (int k = 0; k < 3; ++k) {
      // Edges on the bottom rim have one contactable triangle; every other edge two.
      const Vec3& a = box.vertices()[t.node[k]];
      const Vec3& b = box.vertices()[t.node[(k + 1) % 3]];
      const bool rim = a.z() < 1e-9 && b.z() < 1e-9;
      EXPECT_EQ(t.edge_triangles[k], rim ? 1 : 2);
    }
  }
  std::vector<int> near;
  s.query(Vec3(0.5, 0.5, 1.0), Vec3(0.5, 0.5, 1.0), near);
  EXPECT_FALSE(near.empty());
}

}  // namespace
}  // namespace neurosim::interaction
