// max_principal_strain against closed forms: a uniform stretch by s gives the Green-Lagrange
// strain (s^2 - 1) / 2, a rigid rotation gives none (the small-strain measure would report
// 1 - cos), a field that turns the mesh inside out is counted as inverting it.
#include "fem_test_meshes.hpp"
#include "server/fem/strain.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <stdexcept>

namespace neurosim::fem {
namespace {

// u(x) = (A - I) x for every vertex.
Eigen::VectorXd affine_field(const mesh::TetMesh& m, const Eigen::Matrix3d& a) {
  Eigen::VectorXd u(3 * m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    u.segment<3>(3 * v) = (a - Eigen::Matrix3d::Identity()) * m.vertices()[v];
  }
  return u;
}

mesh::TetMesh test_mesh() {
  testing::BoxSpec s;
  s.nx = s.ny = s.nz = 3;
  s.hi = Eigen::Vector3d(0.02, 0.03, 0.04);
  s.jitter = 0.2;
  return testing::box_mesh(s);
}

TEST(Strain, UniformStretchGivesTheGreenStrain) {
  const mesh::TetMesh m = test_mesh();
  const double stretch = 1.3;  // 30 % elongation along y
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  a(1, 1) = stretch;
  const StrainSummary s = max_principal_strain(m, affine_field(m, a));
  EXPECT_NEAR(s.max_strain, 0.5 * (stretch * stretch - 1.0), 1e-12);
  EXPECT_GE(s.tet, 0);
  EXPECT_EQ(s.inverted, 0);
  // Compression: |(0.6^2 - 1) / 2| = 0.32.
  a(1, 1) = 0.6;
  EXPECT_NEAR(max_principal_strain(m, affine_field(m, a)).max_strain, 0.32, 1e-12);
}

TEST(Strain, RigidRotationHasNoStrain) {
  const mesh::TetMesh m = test_mesh();
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(1.2, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const StrainSummary s = max_principal_strain(m, affine_field(m, r));
  EXPECT_LT(s.max_strain, 1e-13);
  EXPECT_EQ(s.inverted, 0);
}

TEST(Strain, InvertingFieldIsCounted) {
  const mesh::TetMesh m = test_mesh();
  Eigen::Matrix3d a = Eigen::Matrix3d::Identity();
  a(2, 2) = -0.5;  // mirrors every tetrahedron through a plane
  const StrainSummary s = max_principal_strain(m, affine_field(m, a));
  EXPECT_EQ(s.inverted, static_cast<int>(m.num_tets()));
  EXPECT_NEAR(s.max_strain, 0.5 * (1.0 - 0.25), 1e-12);
}

TEST(Strain, BadInputIsRefused) {
  const mesh::TetMesh m = test_mesh();
  EXPECT_THROW(max_principal_strain(m, Eigen::VectorXd::Zero(5)), std::invalid_argument);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * m.num_vertices());
  u[7] = std::numeric_limits<double>::quiet_NaN();
  try {
    max_principal_strain(m, u);
    FAIL() << "a NaN displacement was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("node 2"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace neurosim::fem
