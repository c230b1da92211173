// TriangleBvh (CGAL AABB tree) against brute force over every triangle: the triangles in a box
// and the closest point, on a bumpy closed sphere.
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/triangle_bvh.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

namespace neurosim::fusion {
namespace {

// A closed UV sphere of radius ~0.05 m with bumps, so closest points are not trivial.
void bumpy_sphere(std::vector<mesh::Vec3>& v, std::vector<mesh::Tri>& t) {
  const int nu = 40, nv = 20;
  v.push_back(mesh::Vec3(0, 0, 0.05));
  for (int j = 1; j < nv; ++j)
    for (int i = 0; i < nu; ++i) {
      const double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
      const double r = 0.05 * (1.0 + 0.1 * std::sin(3 * ph) * std::sin(2 * th));
      v.push_back(r * mesh::Vec3(std::sin(th) * std::cos(ph), std::sin(th) * std::sin(ph), std::cos(th)));
    }
  v.push_back(mesh::Vec3(0, 0, -0.05));
  const int south = static_cast<int>(v.size()) - 1;
  auto id = [&](int j, int i) { return 1 + (j - 1) * nu + (i % nu); };
  for (int i = 0; i < nu; ++i) t.push_back({0, id(1, i), id(1, i + 1)});
  for (int j = 1; j < nv - 1; ++j)
    for (int i = 0; i < nu; ++i) {
      t.push_back({id(j, i), id(j + 1, i), id(j + 1, i + 1)});
      t.push_back({id(j, i), id(j + 1, i + 1), id(j, i + 1)});
    }
  for (int i = 0; i < nu; ++i) t.push_back({south, id(nv - 1, i + 1), id(nv - 1, i)});
}

TEST(fusion_triangle_bvh, ClosestPointEqualsBruteForce) {
  std::vector<mesh::Vec3> v;
  std::vector<mesh::Tri> t;
  bumpy_sphere(v, t);
  const TriangleBvh bvh(v, t);
  ASSERT_EQ(bvh.size(), static_cast<int>(t.size()));
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.08, 0.08);
  for (int k = 0; k < 500; ++k) {
    const mesh::Vec3 p(u(rng), u(rng), u(rng));
    double best = std::numeric_limits<double>::infinity();
    for (const auto& tri : t)
      best = std::min(best, (closest_point_on_triangle(p, v[tri[0]], v[tri[1]], v[tri[2]]).point_m - p).norm());
    const ClosestTriangle c = bvh.closest(p);
    EXPECT_NEAR(c.distance_m, best, 1e-12) << "point " << k;
    const auto& tri = t[static_cast<std::size_t>(c.triangle)];
    EXPECT_NEAR((closest_point_on_triangle(p, v[tri[0]], v[tri[1]], v[tri[2]]).point_m - c.point_m).norm(), 0.0, 1e-12);
  }
}

TEST(fusion_triangle_bvh, BoxQueryFindsEveryTriangleNearThePoint) {
  std::vector<mesh::Vec3> v;
  std::vector<mesh::Tri> t;
  bumpy_sphere(v, t);
  const TriangleBvh bvh(v, t);
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.07, 0.07);
  std::vector<int> found;
  found.reserve(t.size());
  int nonempty = 0;
  for (int k = 0; k < 300; ++k) {
    const mesh::Vec3 p(u(rng), u(rng), u(rng));
    const double r = 0.01;
    found.clear();
    bvh.triangles_in_box(p - mesh::Vec3::Constant(r), p + mesh::Vec3::Constant(r), found);
    std::sort(found.begin(), found.end());
    // Every triangle within r of p meets the box; every triangle found meets the box.
    for (std::size_t i = 0; i < t.size(); ++i) {
      const auto& tri = t[i];
      const double d = (closest_point_on_triangle(p, v[tri[0]], v[tri[1]], v[tri[2]]).point_m - p).norm();
      if (d <= r) {
        EXPECT_TRUE(std::binary_search(found.begin(), found.end(), static_cast<int>(i)))
            << "point " << k << " triangle " << i << " at " << d;
      }
    }
    for (int i : found) {
      const auto& tri = t[static_cast<std::size_t>(i)];
      const mesh::Vec3 lo = v[tri[0]].cwiseMin(v[tri[1]]).cwiseMin(v[tri[2]]);
      const mesh::Vec3 hi = v[tri[0]].cwiseMax(v[tri[1]]).cwiseMax(v[tri[2]]);
      EXPECT_TRUE((lo.array() <= (p.array() + r)).all() && (hi.array() >= (p.array() - r)).all());
    }
    nonempty += found.empty() ? 0 : 1;
  }
  EXPECT_GT(nonempty, 20);  // the points do reach the surface
}

TEST(fusion_triangle_bvh, RefusesBadInput) {
  EXPECT_THROW(TriangleBvh({}, {}), std::invalid_argument);
  EXPECT_THROW(TriangleBvh({mesh::Vec3::Zero()}, {{0, 1, 2}}), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
