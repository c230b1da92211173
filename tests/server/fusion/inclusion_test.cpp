// Inclusion decision (paper Algorithm 1): fast == brute force, degenerate geometry, errors.
#include "server/fusion/inclusion.hpp"

#include "fusion_fixtures.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <set>
#include <stdexcept>
#include <string>

namespace neurosim::fusion {
namespace {

using test::structured_box;

void expect_same(const NewBoundary& fast, const NewBoundary& brute, const std::string& what) {
  EXPECT_EQ(fast.triangles, brute.triangles) << what;
  EXPECT_EQ(fast.source_tet, brute.source_tet) << what;
  EXPECT_EQ(fast.stats.intersected_faces, brute.stats.intersected_faces) << what;
  EXPECT_EQ(fast.stats.intersected_tets, brute.stats.intersected_tets) << what;
  EXPECT_EQ(fast.stats.partial_tets, brute.stats.partial_tets) << what;
  EXPECT_EQ(fast.stats.inside_triangles, brute.stats.inside_triangles) << what;
}

// Runs both versions, checks they agree and that S' is outside B and reported once.
NewBoundary both(const mesh::TetMesh& a, const TriangleSurface& b, const std::string& what) {
  const NewBoundary brute = find_new_boundary_bruteforce(a, b);
  const NewBoundary fast = find_new_boundary(a, b);
  expect_same(fast, brute, what);
  std::set<std::array<int, 3>> seen;
  for (std::size_t i = 0; i < fast.triangles.size(); ++i) {
    auto s = fast.triangles[i];
    std::array<int, 3> key{s[0], s[1], s[2]};
    std::sort(key.begin(), key.end());
    EXPECT_TRUE(seen.insert(key).second) << what << ": triangle " << i << " reported twice";
    for (int v : s) {
      EXPECT_LT(test::winding_number(a.vertices()[v], b), 0.5)
          << what << ": S' vertex " << v << " inside B";
    }
  }
  return fast;
}

TEST(fusion_inclusion, InsideTrianglesCountsInteriorFacesPerTetrahedron) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 3, 2, 2);
  const auto b =
      TriangleSurface::of(structured_box(Vec3(0.3, 0.3, 0.3), Vec3(0.6, 0.6, 0.7), 1, 1, 1));
  const NewBoundary s = find_new_boundary(a, b);
  // Each interior face belongs to two tetrahedra: 2 * (4T - S) / 2 == 4T - S.
  std::size_t interior_faces_twice = 0;
  for (const auto& n : a.neighbours())
    for (int k = 0; k < 4; ++k) interior_faces_twice += n[k] >= 0 ? 1 : 0;
  EXPECT_EQ(s.stats.inside_triangles, interior_faces_twice);
  EXPECT_EQ(s.stats.host_tets, a.num_tets());
}

TEST(fusion_inclusion, GenericBoxInsideGivesBoundaryAroundIt) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 6, 6, 6);
  std::mt19937 rng(7);
  const auto b_mesh = test::transformed(structured_box(Vec3(-1, -1, -1), Vec3(1, 1, 1), 2, 2, 2),
                                        test::random_rotation(rng), 0.17, Vec3(0.48, 0.51, 0.53));
  const auto b = TriangleSurface::of(b_mesh, "rotated box");
  const NewBoundary s = both(a, b, "rotated box inside");
  EXPECT_GT(s.triangles.size(), 0u);
  EXPECT_GT(s.stats.intersected_faces, 0u);
  EXPECT_LT(s.stats.tets_checked, a.num_tets());  // box culling did something
  EXPECT_EQ(s.stats.tets_checked + s.stats.tets_culled, a.num_tets());
}

TEST(fusion_inclusion, RandomStructuredPairsAgree) {
  // Random rigid placements and sizes of a small box and a small slab in a structured host
  // (the host's grid planes are exactly representable: many near-coincidences).
  std::mt19937 rng(12345);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 5, 5, 5);
  const auto box = structured_box(Vec3(-1, -1, -1), Vec3(1, 1, 1), 2, 2, 2);
  const auto slab = structured_box(Vec3(-1, -0.3, -0.1), Vec3(1, 0.3, 0.1), 3, 1, 1);
  int nonempty = 0;
  for (int i = 0; i < 60; ++i) {
    const auto& base = (i % 2 == 0) ? box : slab;
    const auto b_mesh = test::transformed(base, test::random_rotation(rng), 0.1 + 0.4 * u(rng),
                                          Vec3(u(rng), u(rng), u(rng)) * 1.2 - Vec3::Constant(0.1));
    const auto b = TriangleSurface::of(b_mesh, "random " + std::to_string(i));
    nonempty += both(a, b, "pair " + std::to_string(i)).triangles.empty() ? 0 : 1;
  }
  EXPECT_GT(nonempty, 40);  // the placements do overlap
}

// B's faces lie on A's grid planes: coplanar faces, shared vertices and edges everywhere.
TEST(fusion_inclusion, CoplanarSharedVerticesAndEdges) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 4, 4, 4);
  const auto b =
      TriangleSurface::of(structured_box(Vec3(0.25, 0.25, 0.25), Vec3(0.75, 0.75, 0.75), 2, 2, 2));
  const NewBoundary s = both(a, b, "aligned box");
  // Touching counts as intersecting: every A face on B's surface, or sharing a vertex with it.
  EXPECT_GT(s.stats.intersected_faces, 0u);
  // A face that touches B at one vertex only is intersected; its opposite face can be S'.
  EXPECT_GT(s.triangles.size(), 0u);
  // And half a cell off the grid (B's faces through A's cells' diagonals' vertices).
  const auto b2 =
      TriangleSurface::of(structured_box(Vec3(0.25, 0.25, 0.25), Vec3(0.75, 0.625, 0.5), 2, 3, 2));
  both(a, b2, "half-aligned box");
}

TEST(fusion_inclusion, EmbeddedTouchingHostOuterSurface) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 4, 4, 4);
  // x = 0 face of B on A's boundary plane.
  const auto b =
      TriangleSurface::of(structured_box(Vec3(0, 0.31, 0.29), Vec3(0.47, 0.69, 0.71), 2, 2, 2));
  EXPECT_GT(both(a, b, "touching outer surface").triangles.size(), 0u);
  // Touching from outside only: B's face on x = 1, B itself outside A.
  const auto c =
      TriangleSurface::of(structured_box(Vec3(1, 0.31, 0.29), Vec3(1.4, 0.69, 0.71), 2, 2, 2));
  const NewBoundary s = both(a, c, "touching from outside");
  EXPECT_GT(s.stats.intersected_faces, 0u);
}

TEST(fusion_inclusion, EmbeddedPartlyOutsideHost) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 5, 5, 5);
  const auto b =
      TriangleSurface::of(structured_box(Vec3(-0.33, 0.31, 0.29), Vec3(0.47, 0.69, 0.71), 3, 2, 2));
  const NewBoundary s = both(a, b, "partly outside");
  EXPECT_GT(s.triangles.size(), 0u);
}

TEST(fusion_inclusion, DisjointGivesEmptyBoundary) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 3, 3, 3);
  const auto b = TriangleSurface::of(structured_box(Vec3(2, 2, 2), Vec3(3, 3, 3), 1, 1, 1));
  const NewBoundary s = both(a, b, "disjoint");
  EXPECT_TRUE(s.triangles.empty());
  EXPECT_EQ(s.stats.tets_culled, a.num_tets());
  EXPECT_EQ(s.stats.intersected_faces, 0u);
  // Boxes overlap but the meshes do not: B in a corner of the box of A turned 45 deg about z.
  const Eigen::Matrix3d rz = Eigen::AngleAxisd(M_PI / 4, Vec3::UnitZ()).toRotationMatrix();
  const auto a_rot = test::transformed(a, rz, 1.0, Vec3::Zero());
  const auto c =
      TriangleSurface::of(structured_box(Vec3(0.5, 0.02, 0.3), Vec3(0.65, 0.12, 0.5), 1, 1, 1));
  const NewBoundary s2 = both(a_rot, c, "boxes overlap, meshes disjoint");
  EXPECT_TRUE(s2.triangles.empty());
  EXPECT_EQ(s2.stats.intersected_faces, 0u);
}

TEST(fusion_inclusion, EmbeddedEnclosingHostOrInsideOneTetGivesEmptyBoundary) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 3, 3, 3);
  const auto big = TriangleSurface::of(structured_box(Vec3(-1, -1, -1), Vec3(2, 2, 2), 1, 1, 1));
  const NewBoundary s = both(a, big, "B encloses A");
  EXPECT_TRUE(s.triangles.empty());
  EXPECT_EQ(s.stats.intersected_faces, 0u);
  // A tiny B strictly inside one tetrahedron meets no face of A: Algorithm 1 adds nothing.
  const auto& t = a.tets()[17];
  Vec3 c = Vec3::Zero();
  for (int v : t) c += 0.25 * a.vertices()[v];
  const auto tiny = TriangleSurface::of(
      structured_box(c - Vec3::Constant(1e-3), c + Vec3::Constant(1e-3), 1, 1, 1));
  const NewBoundary s2 = both(a, tiny, "B inside one tetrahedron");
  EXPECT_TRUE(s2.triangles.empty());
  EXPECT_EQ(s2.stats.intersected_faces, 0u);
}

TEST(fusion_inclusion, OpenEmbeddedSurfaceIsAnErrorNamingItsEdges) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 2, 2, 2);
  auto b = TriangleSurface::of(structured_box(Vec3(0.3, 0.3, 0.3), Vec3(0.6, 0.6, 0.6), 1, 1, 1),
                               "holed");
  const auto removed = b.triangles.back();
  b.triangles.pop_back();
  for (auto run : {0, 1}) {
    try {
      if (run == 0)
        find_new_boundary(a, b);
      else
        find_new_boundary_bruteforce(a, b);
      FAIL() << "open surface accepted";
    } catch (const std::invalid_argument& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("holed"), std::string::npos) << msg;
      EXPECT_NE(msg.find("not closed"), std::string::npos) << msg;
      EXPECT_NE(msg.find("3 open edge"), std::string::npos) << msg;
      for (int k = 0; k < 3; ++k) {
        const int lo = std::min(removed[k], removed[(k + 1) % 3]);
        const int hi = std::max(removed[k], removed[(k + 1) % 3]);
        const std::string edge = "(" + std::to_string(lo) + "," + std::to_string(hi) + ")";
        EXPECT_NE(msg.find(edge), std::string::npos) << msg << " lacks " << edge;
      }
    }
  }
}

TEST(fusion_inclusion, BadEmbeddedSurfaceIsRejected) {
  const auto a = structured_box(Vec3::Zero(), Vec3::Ones(), 2, 2, 2);
  const auto good =
      TriangleSurface::of(structured_box(Vec3(0.3, 0.3, 0.3), Vec3(0.6, 0.6, 0.6), 1, 1, 1));
  auto nan = good;
  nan.vertices_m[nan.triangles[0][1]].y() = std::nan("");
  EXPECT_THROW(find_new_boundary(a, nan), std::invalid_argument);
  auto range = good;
  range.triangles[2][0] = 999;
  EXPECT_THROW(find_new_boundary(a, range), std::invalid_argument);
  // A flat (collinear) triangle pair still closes the surface but is refused by name.
  auto flat = good;
  const int v = flat.triangles[0][0];
  flat.vertices_m.push_back(flat.vertices_m[v]);
  flat.vertices_m.push_back(flat.vertices_m[v] + Vec3(0.01, 0, 0));
  flat.vertices_m.push_back(flat.vertices_m[v] + Vec3(0.02, 0, 0));
  const int n = static_cast<int>(flat.vertices_m.size());
  flat.triangles.push_back({n - 3, n - 2, n - 1});
  flat.triangles.push_back({n - 3, n - 1, n - 2});
  try {
    find_new_boundary(a, flat);
    FAIL() << "degenerate triangle accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("degenerate"), std::string::npos) << e.what();
  }
}

TEST(fusion_inclusion, OutsideTestMatchesAnalyticBox) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  const Eigen::Matrix3d r = test::random_rotation(rng);
  const Vec3 t(0.1, -0.2, 0.3);
  const auto b = TriangleSurface::of(test::transformed(
      structured_box(Vec3(-1, -0.5, -0.7), Vec3(1, 0.5, 0.7), 3, 2, 2), r, 1.0, t));
  int inside = 0;
  for (int i = 0; i < 400; ++i) {
    const Vec3 p(u(rng), u(rng), u(rng));
    const Vec3 local = r.transpose() * (p - t);
    const Vec3 gap = Vec3(1, 0.5, 0.7) - local.cwiseAbs();
    if (std::abs(gap.minCoeff()) < 1e-9) continue;
    const bool in = gap.minCoeff() > 0;
    inside += in ? 1 : 0;
    EXPECT_EQ(outside_closed_surface(p, b), !in) << "point " << p.transpose();
  }
  EXPECT_GT(inside, 20);
  // A point on the surface has no side.
  EXPECT_THROW(outside_closed_surface(b.vertices_m[b.triangles[0][0]], b), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fusion
