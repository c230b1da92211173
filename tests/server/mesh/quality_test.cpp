// Quality report: dihedral angles, radius-edge ratio, inverted and zero-volume counts.
#include "server/mesh/quality.hpp"

#include "tests/server/mesh/mesh_fixtures.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace neurosim::mesh {
namespace {

const double kPi = std::acos(-1.0);

std::vector<Vec3> regular_tet() {
  return {Vec3(1, 1, 1), Vec3(1, -1, -1), Vec3(-1, 1, -1), Vec3(-1, -1, 1)};
}

TEST(MeshQuality, RegularTet) {
  auto v = regular_tet();
  const QualityReport q = quality(v, {Tet{0, 1, 2, 3}});
  const double dihedral = std::acos(1.0 / 3.0) * 180.0 / kPi;  // 70.5288 deg
  EXPECT_NEAR(q.min_dihedral_deg, dihedral, 1e-9);
  EXPECT_NEAR(q.max_dihedral_deg, dihedral, 1e-9);
  EXPECT_NEAR(q.max_radius_edge_ratio, std::sqrt(6.0) / 4.0, 1e-12);
  EXPECT_NEAR(q.mean_radius_edge_ratio, std::sqrt(6.0) / 4.0, 1e-12);
  EXPECT_EQ(q.num_tets, 1);
  EXPECT_EQ(q.num_vertices, 4);
  // Orientation does not change the shape measures, only the inverted count.
  const QualityReport r = quality(v, {Tet{1, 0, 2, 3}});
  EXPECT_EQ(q.inverted + r.inverted, 1);
  EXPECT_NEAR(r.min_dihedral_deg, dihedral, 1e-9);
}

TEST(MeshQuality, CornerTet) {
  // Three right dihedral angles at the corner edges, acos(1/sqrt(3)) at the others.
  const TetQuality q = tet_quality(Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));
  EXPECT_NEAR(q.volume_m3, 1.0 / 6.0, 1e-15);
  EXPECT_NEAR(q.min_dihedral_deg, std::acos(1.0 / std::sqrt(3.0)) * 180.0 / kPi, 1e-9);
  EXPECT_NEAR(q.max_dihedral_deg, 90.0, 1e-9);
  EXPECT_NEAR(q.radius_edge_ratio, std::sqrt(3.0) / 2.0, 1e-12);  // R = sqrt(3)/2, shortest 1
}

TEST(MeshQuality, SliverDetected) {
  // Four points near a square's circumcircle: good radius-edge ratio, terrible angles.
  const double h = 0.01;
  std::vector<Vec3> v{Vec3(0, 0, h), Vec3(1, 0, -h), Vec3(1, 1, h), Vec3(0, 1, -h)};
  const QualityReport q = quality(v, {Tet{0, 1, 2, 3}});
  EXPECT_EQ(q.zero_volume, 0);
  EXPECT_LT(q.min_dihedral_deg, 5.0);
  EXPECT_GT(q.max_dihedral_deg, 175.0);
  EXPECT_LT(q.max_radius_edge_ratio, 0.75);
}

TEST(MeshQuality, RawInputCountsInvertedAndZeroVolume) {
  auto a = testing::grid_cube(2, 1.0);
  std::swap(a.tets[3][0], a.tets[3][1]);
  std::swap(a.tets[9][2], a.tets[9][3]);
  a.tets.push_back(Tet{0, 1, 3, 4});  // bottom face points: coplanar
  const QualityReport q = quality(a.vertices, a.tets);
  EXPECT_EQ(q.inverted, 2);
  EXPECT_EQ(q.zero_volume, 1);
  EXPECT_EQ(q.num_tets, 49);
  EXPECT_EQ(q.num_vertices, 27);
  // Kuhn tetrahedra: dihedral angles 45, 60 and 90 deg; radius-edge sqrt(3)/2.
  EXPECT_NEAR(q.min_dihedral_deg, 45.0, 1e-9);
  EXPECT_NEAR(q.max_dihedral_deg, 90.0, 1e-9);
  EXPECT_NEAR(q.max_radius_edge_ratio, std::sqrt(3.0) / 2.0, 1e-12);
  const std::string s = q.summary();
  EXPECT_NE(s.find("49 tets"), std::string::npos) << s;
  EXPECT_NE(s.find("inverted 2"), std::string::npos) << s;
  EXPECT_NE(s.find("zero-volume 1"), std::string::npos) << s;
  EXPECT_NE(s.find("[45.00, 90.00]"), std::string::npos) << s;
}

TEST(MeshQuality, FromTetMeshMatchesRaw) {
  auto a = testing::grid_cube(3, 0.5);
  const TetMesh m = TetMesh::build(a.vertices, a.tets);
  const QualityReport q = quality(m), r = quality(a.vertices, a.tets);
  EXPECT_EQ(q.num_tets, r.num_tets);
  EXPECT_DOUBLE_EQ(q.min_dihedral_deg, r.min_dihedral_deg);
  EXPECT_DOUBLE_EQ(q.mean_radius_edge_ratio, r.mean_radius_edge_ratio);
  EXPECT_EQ(q.inverted, 0);
}

TEST(MeshQuality, BadInputThrows) {
  auto v = regular_tet();
  EXPECT_THROW(quality(v, {Tet{0, 1, 2, 4}}), std::invalid_argument);
  v[2].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(quality(v, {Tet{0, 1, 2, 3}}), std::invalid_argument);
}

TEST(MeshQuality, CollapsedTetHasNoNaN) {
  const TetQuality q = tet_quality(Vec3(0, 0, 0), Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));
  EXPECT_FALSE(std::isnan(q.min_dihedral_deg));
  EXPECT_FALSE(std::isnan(q.radius_edge_ratio));
  EXPECT_EQ(q.volume_m3, 0.0);
}

}  // namespace
}  // namespace neurosim::mesh
