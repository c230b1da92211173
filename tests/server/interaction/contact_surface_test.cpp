// ContactSurface and closest_on_triangle: the closest point against a dense sampling of the
// triangle (brute force), its feature and weights; the contactable triangles and edge incidence
// of a box's surface; the spread load's weights (sum, first moment, continuity); the projection
// along interpolated normals (the flat closest point where the normals agree, continuous across
// a crease).
#include "server/interaction/contact_surface.hpp"

#include "server/fem/fem_test_meshes.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
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

// The box's top face (z = 1, cells of 1/3) and its contactable surface, every non-bottom
// surface node a slot.
struct TopFace {
  mesh::TetMesh box = fem::testing::box_mesh(fem::testing::BoxSpec{3, 3, 3});
  std::vector<int> slot, fixed;
  ContactSurface surface;
  TopFace() {
    slot.assign(box.num_vertices(), -1);
    int slots = 0;
    for (int v : box.surface_vertices()) {
      if (box.vertices()[v].z() < 1e-9) {
        fixed.push_back(v);
      } else {
        slot[v] = slots++;
      }
    }
    std::sort(fixed.begin(), fixed.end());
    surface = ContactSurface(ContactSurfaceDefinition{&box, &slot, &fixed});
  }
};

TEST(interaction_contact_surface, BoxSurfaceTrianglesAndEdgeIncidence) {
  const TopFace f;  // every surface node but the bottom (z = 0, fixed) is a contact slot
  const mesh::TetMesh& box = f.box;
  const ContactSurface& s = f.surface;
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


// A tool's candidates: query_tool lists the triangles of query(tip box) and query_near(shaft
// box) whose bounding sphere is within the reach of the axis, each once, by rank.
TEST(interaction_contact_surface, QueryToolListsTheTwoBoxesTrianglesNearTheAxisByRank) {
  const TopFace f;
  const ContactSurface& s = f.surface;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-0.2, 1.2);
  std::vector<int> tip, shaft, ranks;
  std::size_t listed = 0, kept = 0;
  for (int q = 0; q < 300; ++q) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng));
    const double h = 0.05 + 0.2 * std::abs(u(rng));
    const double near = 0.02 + 0.2 * std::abs(u(rng)), sphere = 0.3 * std::abs(u(rng));
    const Vec3 lo = a - Vec3::Constant(h), hi = a + Vec3::Constant(h);
    const Vec3 near_lo = a.cwiseMin(b) - Vec3::Constant(h), near_hi = a.cwiseMax(b) + Vec3::Constant(h);
    const bool has_near = q % 4 != 0;
    tip.clear();
    shaft.clear();
    ranks.clear();
    s.query(lo, hi, tip);
    if (has_near) s.query_near(near_lo, near_hi, a, b, near, shaft);
    s.query_tool(lo, hi, has_near, near_lo, near_hi, a, b, near, sphere, ranks);
    std::vector<int> expected;
    for (const auto* list : {&tip, &shaft})
      for (int t : *list) {
        const Vec3& c = s.centroid(t);
        const double bound = (s.radius_m(t) + sphere) * (1.0 + 1e-6);
        if ((c - closest_on_segment(c, a, b)).squaredNorm() <= bound * bound) expected.push_back(t);
      }
    std::sort(expected.begin(), expected.end(),
              [&](int x, int y) { return s.query_rank(x) < s.query_rank(y); });
    expected.erase(std::unique(expected.begin(), expected.end()), expected.end());
    ASSERT_EQ(ranks.size(), expected.size()) << "query " << q;
    for (std::size_t k = 0; k < ranks.size(); ++k) {
      ASSERT_EQ(s.ranked_triangle(ranks[k]), expected[k]) << "query " << q;
      ASSERT_EQ(s.query_rank(expected[k]), ranks[k]);
    }
    listed += tip.size() + shaft.size();
    kept += ranks.size();
  }
  EXPECT_LT(kept, listed) << "the sphere test dropped nothing";
  EXPECT_THROW(s.query_tool(Vec3::Zero(), Vec3::Zero(), false, Vec3::Zero(), Vec3::Zero(),
                            Vec3::Zero(), Vec3::Zero(), 0.1, -1.0, ranks),
               std::invalid_argument);
}

TEST(interaction_contact_surface, SpreadLoadWeightsAreConsistentAndContinuous) {
  const TopFace f;
  std::vector<int> scratch;
  scratch.reserve(f.surface.triangles().size());
  const double rho = 0.25;
  auto weights_at = [&](const Vec3& p) {
    SpreadLoad load;
    EXPECT_TRUE(f.surface.spread(p, Vec3::UnitZ(), rho, scratch, load));
    EXPECT_EQ(load.dropped, 0);
    std::vector<double> w(f.box.num_vertices(), 0.0);
    double sum = 0.0;
    Vec3 moment = Vec3::Zero();
    for (int k = 0; k < load.nodes; ++k) {
      EXPECT_GE(load.weight[k], 0.0);
      EXPECT_EQ(load.slot[k], f.slot[load.node[k]]);
      // Only the top face's nodes: the side faces are at 90 degrees to n.
      EXPECT_NEAR(f.box.vertices()[load.node[k]].z(), 1.0, 1e-12);
      w[load.node[k]] = load.weight[k];
      sum += load.weight[k];
      moment += load.weight[k] * f.box.vertices()[load.node[k]];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    // Linear shape functions reproduce position: the first moment is the kernel's mean point,
    // p itself for a kernel wholly on the plane (up to the midpoint rule's asymmetry).
    EXPECT_LT((moment - p).norm(), 0.02 * rho) << p.transpose();
    return w;
  };
  // At a vertex, on an edge, on a face, and across the edge (1/3, y) between two triangles:
  // a step of 1e-7 changes no weight by more than 1e-5 (continuous, no feature switch).
  for (const Vec3& p : {Vec3(1.0 / 3, 1.0 / 3, 1), Vec3(0.5, 1.0 / 3, 1), Vec3(0.45, 0.4, 1),
                        Vec3(0.5, 0.5, 1)}) {
    const auto w0 = weights_at(p);
    for (const Vec3& step : {Vec3(1e-7, 0, 0), Vec3(0, 1e-7, 0), Vec3(-7e-8, 7e-8, 0)}) {
      const auto w1 = weights_at(p + step);
      for (std::size_t v = 0; v < w0.size(); ++v) EXPECT_NEAR(w1[v], w0[v], 1e-5) << v;
    }
  }
  // Spread over more than the point's triangle: a vertex keeps well under all of the load.
  SpreadLoad at_vertex;
  ASSERT_TRUE(f.surface.spread(Vec3(1.0 / 3, 1.0 / 3, 1), Vec3::UnitZ(), rho, scratch, at_vertex));
  EXPECT_GT(at_vertex.nodes, 3);
  EXPECT_LT(at_vertex.weight[0], 0.8);
}

TEST(interaction_contact_surface, ProjectionAlongNormalsIsFlatWhereTheyAgreeAndContinuousAcrossACrease) {
  // Equal normals: the flat triangle's closest point and height.
  const std::array<Vec3, 3> p{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  const std::array<Vec3, 3> up{Vec3::UnitZ(), Vec3::UnitZ(), Vec3::UnitZ()};
  TrianglePoint at;
  Vec3 n;
  double h = 0.0;
  ASSERT_TRUE(project_along_normals(Vec3(0.2, 0.3, 0.7), p, up, at, n, h));
  EXPECT_LT((at.point_m - Vec3(0.2, 0.3, 0)).norm(), 1e-12);
  EXPECT_NEAR(h, 0.7, 1e-12);
  EXPECT_LT((n - Vec3::UnitZ()).norm(), 1e-12);
  EXPECT_FALSE(project_along_normals(Vec3(0.8, 0.8, 0.7), p, up, at, n, h));  // beyond the edge
  // A ridge along the y axis: the left flank rises to it, the right one falls (30 degrees each
  // side); the edge's nodes carry the mean normal (vertical). A centre moving across the ridge
  // projects on one flank, then the other, with the same point, normal and height at the edge.
  const double s = std::tan(M_PI / 6);
  const Vec3 a(0, 0, 0), b(0, 1, 0), l(-1, 0.5, -s), r(1, 0.5, -s);
  const std::array<Vec3, 3> left{a, b, l}, right{a, r, b};  // outward (up) orientation
  const Vec3 nl = (b - a).cross(l - a).normalized(), nr = (r - a).cross(b - a).normalized();
  ASSERT_GT(nl.z(), 0.0);
  ASSERT_GT(nr.z(), 0.0);
  const std::array<Vec3, 3> nn_left{Vec3::UnitZ(), Vec3::UnitZ(), nl};
  const std::array<Vec3, 3> nn_right{Vec3::UnitZ(), nr, Vec3::UnitZ()};
  double last_h = 0.0;
  Vec3 last_n = Vec3::Zero();
  int found = 0;
  for (int i = -20; i <= 20; ++i) {
    const Vec3 c(1e-3 * i, 0.5, 0.6);
    TrianglePoint tl, tr;
    Vec3 n_l, n_r;
    double h_l = 0.0, h_r = 0.0;
    const bool on_l = project_along_normals(c, left, nn_left, tl, n_l, h_l);
    const bool on_r = project_along_normals(c, right, nn_right, tr, n_r, h_r);
    ASSERT_TRUE(on_l || on_r) << i;  // no gap between the flanks
    const double hc = on_l ? h_l : h_r;
    const Vec3 nc = on_l ? n_l : n_r;
    if (found++ > 0) {
      EXPECT_NEAR(hc, last_h, 2e-3) << i;        // 1 um steps: no jump in height
      EXPECT_LT((nc - last_n).norm(), 1e-2) << i;  // nor in the normal
    }
    last_h = hc;
    last_n = nc;
  }
}

}  // namespace
}  // namespace neurosim::interaction
