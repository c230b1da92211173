// Mesh generators (server/mesh/generate.hpp): CGAL Mesh_3 meshes of the paper's cube and
// cylinder at a requested vertex count, reproducible for a given seed, valid, and refusing bad
// input with a clear message.
#include "server/mesh/generate.hpp"
#include "server/mesh/quality.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace neurosim::mesh {
namespace {

double total_volume(const TetMesh& m) {
  double v = 0.0;
  for (int t = 0; t < static_cast<int>(m.num_tets()); ++t) v += m.tet_volume(t);
  return v;
}

TEST(MeshGenerate, BoxNearTargetValidAndFillsTheBox) {
  MeshingOptions o;
  o.target_vertices = 400;
  const GeneratedMesh g = generate_box(Vec3::Zero(), Vec3(0.1, 0.1, 0.1), o);
  const double n = static_cast<double>(g.mesh.num_vertices());
  EXPECT_NEAR(n, 400, 0.05 * 400) << "cell size " << g.cell_size_m << " after " << g.attempts;
  const QualityReport q = quality(g.mesh);
  EXPECT_EQ(q.inverted, 0);
  EXPECT_EQ(q.zero_volume, 0);
  EXPECT_GT(q.min_dihedral_deg, 1.0) << q.summary();
  // A polyhedral domain with protected edges: the tetrahedra fill the box exactly.
  EXPECT_NEAR(total_volume(g.mesh), 1e-3, 1e-9);
  EXPECT_FALSE(g.optimization_time_limited);
  // The estimates the size limit uses are above what the mesher made (at that cell size, and
  // for that target), by less than a factor 4 (most for small meshes, where the surface counts).
  MeshingOptions at_size;
  at_size.cell_size_m = g.cell_size_m;
  const double tets = static_cast<double>(g.mesh.num_tets());
  EXPECT_GE(expected_tetrahedra(Vec3(0.1, 0.1, 0.1), at_size), tets);
  EXPECT_LT(expected_tetrahedra(Vec3(0.1, 0.1, 0.1), at_size), 4.0 * tets);
  EXPECT_GE(expected_tetrahedra(Vec3(0.1, 0.1, 0.1), o), tets);
  EXPECT_LT(expected_tetrahedra(Vec3(0.1, 0.1, 0.1), o), 4.0 * tets);
}

TEST(MeshGenerate, CylinderNearTargetAndCloseToItsVolume) {
  MeshingOptions o;
  o.target_vertices = 206;  // the paper's Table 2a cylinder
  const double r = 0.015, h = 0.06;
  const GeneratedMesh g = generate_cylinder(Vec3(0.05, 0.02, 0.05), Vec3(0, h, 0), r, o);
  EXPECT_NEAR(static_cast<double>(g.mesh.num_vertices()), 206, 0.05 * 206);
  const QualityReport q = quality(g.mesh);
  EXPECT_EQ(q.inverted, 0);
  EXPECT_EQ(q.zero_volume, 0);
  // The rim is a polygon: the volume is a little below pi r^2 h, never above.
  const double exact = M_PI * r * r * h;
  EXPECT_LT(total_volume(g.mesh), exact * (1.0 + 1e-9));
  EXPECT_GT(total_volume(g.mesh), 0.95 * exact);
}

// Same seed, same mesh: bit-identical vertices and tetrahedra (the sliver steps' wall-clock limit
// is far above what this size needs, so machine load cannot change the result).
TEST(MeshGenerate, SameSeedGivesTheSameMesh) {
  MeshingOptions o;
  o.target_vertices = 300;
  o.seed = 7;
  const GeneratedMesh a = generate_box(Vec3::Zero(), Vec3(0.1, 0.05, 0.08), o);
  const GeneratedMesh b = generate_box(Vec3::Zero(), Vec3(0.1, 0.05, 0.08), o);
  ASSERT_EQ(a.mesh.num_vertices(), b.mesh.num_vertices());
  ASSERT_EQ(a.mesh.num_tets(), b.mesh.num_tets());
  for (std::size_t v = 0; v < a.mesh.num_vertices(); ++v) {
    ASSERT_EQ(a.mesh.vertices()[v], b.mesh.vertices()[v]) << "vertex " << v;
  }
  for (std::size_t t = 0; t < a.mesh.num_tets(); ++t) {
    ASSERT_EQ(a.mesh.tets()[t], b.mesh.tets()[t]) << "tetrahedron " << t;
  }
  EXPECT_FALSE(a.optimization_time_limited);
}

// An absurd request is refused before the mesher runs (these would mesh for hours or run out of
// memory), naming the option and the limit.
TEST(MeshGenerate, AbsurdSizesAreRefusedBeforeMeshing) {
  const auto refused = [](auto&& f) -> std::string {
    const auto t0 = std::chrono::steady_clock::now();
    std::string msg = "no error";
    try {
      f();
    } catch (const std::invalid_argument& e) {
      msg = e.what();
    }
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2.0);
    return msg;
  };
  MeshingOptions tiny;
  tiny.cell_size_m = 1e-5;
  std::string msg = refused([&] { generate_box(Vec3::Zero(), Vec3::Ones(), tiny); });
  EXPECT_EQ(msg.rfind("cell_size_m: 1e-05 m in a 1 x 1 x 1 m generated box gives about 1e+16 "
                      "tetrahedra, above the limit of 2e+06 (max_tetrahedra)",
                      0),
            0u)
      << msg;
  // A cylinder this fine also overflowed the int count of rim segments before.
  tiny.cell_size_m = 1e-12;
  msg = refused([&] { generate_cylinder(Vec3::Zero(), Vec3(0, 1, 0), 1.0, tiny); });
  EXPECT_EQ(msg.rfind("cell_size_m: 1e-12 m in a 2 x 2 x 1 m generated cylinder", 0), 0u) << msg;
  MeshingOptions many;
  many.target_vertices = 2000000000;
  msg = refused([&] { generate_box(Vec3::Zero(), Vec3::Ones(), many); });
  EXPECT_EQ(msg.rfind("target_vertices: 2000000000 gives about 1.2e+10 tetrahedra", 0), 0u) << msg;
  MeshingOptions segments;
  segments.target_vertices = 100;
  segments.circle_segments = 1000000000;
  msg = refused([&] { generate_cylinder(Vec3::Zero(), Vec3(0, 1, 0), 0.1, segments); });
  EXPECT_NE(msg.find("circle_segments must be in [3, 4096]"), std::string::npos) << msg;
}

// The sliver steps stop at their wall-clock limit, and say so.
TEST(MeshGenerate, SliverStepsStopAtTheirTimeLimit) {
  MeshingOptions o;
  o.cell_size_m = 0.01;
  o.optimization_time_limit_s = 1e-6;
  const GeneratedMesh g = generate_box(Vec3::Zero(), Vec3(0.1, 0.1, 0.1), o);
  EXPECT_TRUE(g.optimization_time_limited);
  EXPECT_GT(g.mesh.num_tets(), 100u);  // still a valid mesh, built and checked
  o.optimization_time_limit_s = -1.0;
  EXPECT_THROW(generate_box(Vec3::Zero(), Vec3(0.1, 0.1, 0.1), o), std::invalid_argument);
}

TEST(MeshGenerate, BadInputIsRefusedWithAMessage) {
  MeshingOptions o;
  o.target_vertices = 100;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  auto message_of = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_NE(message_of([&] { generate_box(Vec3::Zero(), Vec3(0.1, 0.0, 0.1), o); }), "");
  EXPECT_NE(message_of([&] { generate_box(Vec3(nan, 0, 0), Vec3(0.1, 0.1, 0.1), o); }), "");
  EXPECT_NE(message_of([&] { generate_box(Vec3::Zero(), Vec3(inf, 0.1, 0.1), o); }), "");
  EXPECT_NE(message_of([&] { generate_cylinder(Vec3::Zero(), Vec3(0, 0.1, 0), -0.01, o); }), "");
  EXPECT_NE(message_of([&] { generate_cylinder(Vec3::Zero(), Vec3::Zero(), 0.01, o); }), "");
  EXPECT_NE(message_of([&] { generate_cylinder(Vec3::Zero(), Vec3(0, 0.1, 0), nan, o); }), "");
  MeshingOptions bad;
  bad.target_vertices = -5;
  EXPECT_NE(message_of([&] { generate_box(Vec3::Zero(), Vec3::Ones(), bad); }), "");
  bad.target_vertices = 0;
  bad.cell_size_m = 0.0;  // neither a target nor a size
  EXPECT_NE(message_of([&] { generate_box(Vec3::Zero(), Vec3::Ones(), bad); }), "");
}

}  // namespace
}  // namespace neurosim::mesh
