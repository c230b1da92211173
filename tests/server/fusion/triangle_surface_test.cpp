// Closed-surface checks for the embedded mesh B.
#include "server/fusion/triangle_surface.hpp"

#include "fusion_fixtures.hpp"

#include <gtest/gtest.h>

namespace neurosim::fusion {
namespace {

TEST(fusion_triangle_surface, TetMeshSurfaceIsClosed) {
  const auto m = test::structured_box(Vec3::Zero(), Vec3::Ones(), 3, 2, 2);
  const auto s = TriangleSurface::of(m, "box");
  EXPECT_EQ(s.triangles, m.surface());
  EXPECT_TRUE(open_edges(s).empty());
  EXPECT_NO_THROW(validate_closed(s));
}

TEST(fusion_triangle_surface, HoleEdgesAreListed) {
  const auto m = test::structured_box(Vec3::Zero(), Vec3::Ones(), 2, 2, 2);
  auto s = TriangleSurface::of(m, "box");
  const auto t = s.triangles[5];
  s.triangles.erase(s.triangles.begin() + 5);
  const auto open = open_edges(s);
  ASSERT_EQ(open.size(), 3u);
  for (const auto& e : open) {
    EXPECT_LT(e.v0, e.v1);
    EXPECT_EQ(e.triangles, 1);
    const bool in_t =
        std::count(t.begin(), t.end(), e.v0) == 1 && std::count(t.begin(), t.end(), e.v1) == 1;
    EXPECT_TRUE(in_t) << e.v0 << "," << e.v1;
  }
  EXPECT_THROW(validate_closed(s), std::invalid_argument);
  s.triangles.clear();
  EXPECT_THROW(validate_closed(s), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
