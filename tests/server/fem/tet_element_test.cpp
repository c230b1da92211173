// Constant-strain tetrahedron: symmetry, rigid-body modes, agreement with B^T D B V and with
// finite differences of the strain energy; bad elements give clear errors (bad materials:
// material_test.cpp).
#include "server/fem/tet_element.hpp"
#include "server/fem/material.hpp"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <cmath>
#include <limits>
#include <random>

namespace neurosim::fem {
namespace {

Material brain() { return Material{1.0e6, 0.4, "brain"}; }

// Irregular tetrahedra: random points, reordered to positive volume, rejected when flat.
std::vector<TetNodes> random_tets(int count) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.01, 0.01);  // ~cm-sized, like tissue meshes
  std::vector<TetNodes> out;
  while (static_cast<int>(out.size()) < count) {
    TetNodes x;
    for (auto& p : x) {
      p = Eigen::Vector3d(u(rng), u(rng), u(rng));
    }
    if (tet_quality(x).volume_m3 < 0.0) {
      std::swap(x[2], x[3]);
    }
    if (tet_quality(x).mean_ratio > 0.2) {
      out.push_back(x);
    }
  }
  return out;
}

TEST(FemElement, StiffnessIsSymmetricWithSixRigidModes) {
  for (const TetNodes& x : random_tets(20)) {
    const ElementMatrix k = tet_stiffness(x, brain());
    EXPECT_LE((k - k.transpose()).cwiseAbs().maxCoeff(), 1e-14 * k.cwiseAbs().maxCoeff());
    Eigen::SelfAdjointEigenSolver<ElementMatrix> eig(k);
    const auto& ev = eig.eigenvalues();  // ascending
    const double scale = ev(11);
    for (int i = 0; i < 6; ++i) {
      EXPECT_LE(std::abs(ev(i)), 1e-12 * scale) << "eigenvalue " << i;
    }
    EXPECT_GT(ev(6), 1e-6 * scale) << "a seventh zero mode: element would be singular";
    // The six zero modes are exactly the rigid motions: translations and rotations.
    for (int mode = 0; mode < 6; ++mode) {
      ElementVector u;
      for (int a = 0; a < 4; ++a) {
        Eigen::Vector3d ua = Eigen::Vector3d::Zero();
        if (mode < 3) {
          ua(mode) = 1.0;
        } else {
          ua = Eigen::Vector3d::Unit(mode - 3).cross(x[a]);
        }
        u.segment<3>(3 * a) = ua;
      }
      EXPECT_LE((k * u).norm(), 1e-12 * scale * u.norm()) << "rigid mode " << mode;
    }
  }
}

TEST(FemElement, ClosedFormEqualsBtDBV) {
  for (const TetNodes& x : random_tets(20)) {
    const TetGeometry g = tet_geometry(x);
    const Eigen::Matrix<double, 6, 12> b = strain_displacement(g);
    const ElementMatrix reference = g.volume_m3 * b.transpose() * elasticity_matrix(brain()) * b;
    const ElementMatrix k = tet_stiffness(x, brain());
    EXPECT_LE((k - reference).cwiseAbs().maxCoeff(), 1e-12 * reference.cwiseAbs().maxCoeff());
  }
}

TEST(FemElement, StiffnessIsSecondDerivativeOfStrainEnergy) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1e-4, 1e-4);
  for (const TetNodes& x : random_tets(5)) {
    const ElementMatrix k = tet_stiffness(x, brain());
    ElementVector u0;
    for (int i = 0; i < 12; ++i) {
      u0(i) = u(rng);
    }
    const double h = 1e-5;  // m
    ElementMatrix fd;
    for (int i = 0; i < 12; ++i) {
      for (int j = 0; j < 12; ++j) {
        auto energy = [&](double si, double sj) {
          ElementVector v = u0;
          v(i) += si * h;
          v(j) += sj * h;
          return tet_strain_energy(x, brain(), v);
        };
        fd(i, j) = (energy(1, 1) - energy(1, -1) - energy(-1, 1) + energy(-1, -1)) / (4 * h * h);
      }
    }
    EXPECT_LE((k - fd).cwiseAbs().maxCoeff(), 1e-6 * k.cwiseAbs().maxCoeff());
    // And the energy itself is 1/2 u^T K u.
    EXPECT_NEAR(tet_strain_energy(x, brain(), u0), 0.5 * u0.dot(k * u0), 1e-12 * u0.dot(k * u0));
  }
}

TEST(FemElement, LinearFieldGivesItsStrain) {
  // u = A x: strain is sym(A), whatever the element shape.
  Eigen::Matrix3d a;
  a << 1e-3, 2e-3, -1e-3, 0.5e-3, -2e-3, 1e-3, 3e-3, 0, 1e-3;
  for (const TetNodes& x : random_tets(5)) {
    ElementVector u;
    for (int n = 0; n < 4; ++n) {
      u.segment<3>(3 * n) = a * x[n];
    }
    const Eigen::Matrix<double, 6, 1> eps = strain_displacement(tet_geometry(x)) * u;
    const Eigen::Matrix3d e = 0.5 * (a + a.transpose());
    Eigen::Matrix<double, 6, 1> expected;
    expected << e(0, 0), e(1, 1), e(2, 2), 2 * e(0, 1), 2 * e(1, 2), 2 * e(2, 0);
    EXPECT_LE((eps - expected).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(FemElement, BadElementsAreRefusedByName) {
  TetNodes x{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 0, 0), Eigen::Vector3d(0, 1, 0),
             Eigen::Vector3d(0, 0, 1)};
  EXPECT_NO_THROW(tet_geometry(x, 7));
  TetNodes inverted = x;
  std::swap(inverted[2], inverted[3]);
  try {
    tet_geometry(inverted, 7);
    FAIL() << "inverted tetrahedron accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tetrahedron 7"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("inverted"), std::string::npos) << e.what();
  }
  TetNodes flat = x;
  flat[3] = Eigen::Vector3d(0.3, 0.3, 0.0);
  EXPECT_THROW(tet_geometry(flat, 8), std::invalid_argument);
  for (double bad : {std::nan(""), std::numeric_limits<double>::infinity()}) {
    TetNodes y = x;
    y[2].y() = bad;
    EXPECT_THROW(tet_stiffness(y, brain(), 9), std::invalid_argument);
  }
  ElementVector u = ElementVector::Zero();
  u(4) = std::nan("");
  EXPECT_THROW(tet_strain_energy(x, brain(), u), std::invalid_argument);
}

TEST(FemElement, SliverIsAcceptedAndReported) {
  // Four nearly coplanar points spread out: a classic sliver (tiny dihedral angles).
  const double eps = 1e-3;
  TetNodes x{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1, 1, 0), Eigen::Vector3d(1, 0, eps),
             Eigen::Vector3d(0, 1, eps)};
  if (tet_quality(x).volume_m3 < 0) {
    std::swap(x[2], x[3]);
  }
  const TetQuality q = tet_quality(x);
  std::printf("sliver: volume %.3e m^3, mean ratio %.3e, dihedral [%.4f, %.4f] deg\n", q.volume_m3,
              q.mean_ratio, q.min_dihedral_deg, q.max_dihedral_deg);
  EXPECT_LT(q.mean_ratio, 1e-2);
  EXPECT_GT(q.max_dihedral_deg, 179.0);
  const ElementMatrix k = tet_stiffness(x, brain());
  EXPECT_TRUE(k.allFinite());
  // Regular tetrahedron: mean ratio 1, all dihedral angles acos(1/3).
  TetNodes r{Eigen::Vector3d(1, 1, 1), Eigen::Vector3d(1, -1, -1), Eigen::Vector3d(-1, 1, -1),
             Eigen::Vector3d(-1, -1, 1)};
  if (tet_quality(r).volume_m3 < 0) {
    std::swap(r[2], r[3]);
  }
  EXPECT_NEAR(tet_quality(r).mean_ratio, 1.0, 1e-12);
  EXPECT_NEAR(tet_quality(r).min_dihedral_deg,
              std::acos(1.0 / 3.0) * 180.0 / 3.14159265358979323846, 1e-9);
}

}  // namespace
}  // namespace neurosim::fem
