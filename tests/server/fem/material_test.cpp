// Material and MaterialMap: invalid materials name themselves; the Lamé parameters and the
// elasticity matrix D against the isotropic compliance written independently (1/E, -nu/E, 1/G);
// a map's per-tetrahedron ids and elements checked, naming the tetrahedron or the materials.
#include "server/fem/material.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/LU>

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace neurosim::fem {
namespace {

using neurosim::testing::contains;
using neurosim::testing::message_of;

Material brain() { return Material{1.0e6, 0.4, "brain"}; }

TEST(FemMaterial, InvalidMaterialsNameThemselves) {
  EXPECT_NO_THROW(brain().validate());
  const double nan = std::nan(""), inf = std::numeric_limits<double>::infinity();
  for (auto [e, nu] : std::vector<std::pair<double, double>>{{0.0, 0.3},
                                                             {-1.0, 0.3},
                                                             {nan, 0.3},
                                                             {inf, 0.3},
                                                             {1e6, 0.5},
                                                             {1e6, -1.0},
                                                             {1e6, 0.7},
                                                             {1e6, nan},
                                                             {1e6, -inf}}) {
    Material m{e, nu, "skull"};
    try {
      m.validate();
      FAIL() << "accepted E=" << e << " nu=" << nu;
    } catch (const std::invalid_argument& ex) {
      EXPECT_NE(std::string(ex.what()).find("skull"), std::string::npos) << ex.what();
    }
  }
  const Material m{2.0e6, 0.25, "m"};
  EXPECT_NEAR(m.shear_modulus_pa(), 0.8e6, 1e-9);
  EXPECT_NEAR(m.lame_lambda_pa(), 0.8e6, 1e-9);
  EXPECT_NO_THROW(Material({1.0, 0.4999, "nearly incompressible"}).validate());
}

// D is the inverse of the engineering compliance S (Voigt xx, yy, zz, xy, yz, zx with
// gamma = 2 eps): a uniaxial stress gives the strain sigma/E along it and -nu sigma/E across it,
// a shear stress tau the engineering strain tau/G. Near incompressibility too (nu = 0.499).
TEST(FemMaterial, ElasticityMatrixInvertsTheIsotropicCompliance) {
  for (const Material& m :
       {brain(), Material{3000.0, 0.45, "soft"}, Material{1.5e10, 0.3, "bone"},
        Material{1.0e4, 0.499, "nearly incompressible"}, Material{1.0e6, -0.3, "auxetic"}}) {
    const double e = m.youngs_modulus_pa, nu = m.poisson_ratio, g = e / (2.0 * (1.0 + nu));
    Eigen::Matrix<double, 6, 6> s = Eigen::Matrix<double, 6, 6>::Zero();
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) s(i, j) = (i == j ? 1.0 : -nu) / e;
      s(3 + i, 3 + i) = 1.0 / g;
    }
    const Eigen::Matrix<double, 6, 6> d = elasticity_matrix(m);
    EXPECT_LT((d * s - Eigen::Matrix<double, 6, 6>::Identity()).norm(), 1e-9) << m.name;
    EXPECT_LT((d - d.transpose()).norm(), 1e-15 * d.norm()) << m.name;
    // The strain of a uniaxial stress of 1 kPa, from D alone.
    Eigen::Matrix<double, 6, 1> sigma = Eigen::Matrix<double, 6, 1>::Zero();
    sigma(0) = 1000.0;
    const Eigen::Matrix<double, 6, 1> eps = d.partialPivLu().solve(sigma);
    EXPECT_NEAR(eps(0), 1000.0 / e, 1e-9 * std::abs(1000.0 / e)) << m.name;
    EXPECT_NEAR(eps(1), -nu * 1000.0 / e, 1e-9 * std::abs(1000.0 / e)) << m.name;
    EXPECT_NEAR(eps(2), eps(1), 1e-9 * std::abs(1000.0 / e)) << m.name;
    EXPECT_NEAR(eps.tail<3>().norm(), 0.0, 1e-9 * std::abs(1000.0 / e)) << m.name;
  }
  EXPECT_THROW(elasticity_matrix(Material{1e6, 0.5, "locked"}), std::invalid_argument);
}

TEST(FemMaterialMap, UniformAndPerTetrahedron) {
  const MaterialMap uniform = MaterialMap::uniform(brain());
  EXPECT_NO_THROW(uniform.validate(5));
  EXPECT_EQ(uniform.of_tet(4).name, "brain");
  const MaterialMap map =
      MaterialMap::per_tet({brain(), Material{2.0e5, 0.45, "artery"}}, {0, 1, 1, 0});
  EXPECT_NO_THROW(map.validate(4));
  EXPECT_EQ(map.of_tet(0).name, "brain");
  EXPECT_EQ(map.of_tet(2).name, "artery");
  EXPECT_EQ(map.element(), Element::kLinearTet);
}

TEST(FemMaterialMap, BadMapsNameTheTetrahedronOrTheMaterials) {
  EXPECT_PRED2(contains, message_of([] { MaterialMap{}.validate(1); }), "no material");
  const Material artery{2.0e5, 0.45, "artery"};
  EXPECT_PRED2(contains, message_of([&] {
                 MaterialMap::per_tet({brain(), artery}, {0, 1, 1}).validate(4);
               }),
               "3 per-tetrahedron material ids for a mesh of 4 tetrahedra");
  EXPECT_PRED2(contains, message_of([&] {
                 MaterialMap::per_tet({brain(), artery}, {0, 1, 2, 0}).validate(4);
               }),
               "tetrahedron 2 has material id 2, but only 2 materials exist");
  EXPECT_PRED2(contains, message_of([&] {
                 MaterialMap::per_tet({brain(), artery}, {0, -1, 1, 0}).validate(4);
               }),
               "tetrahedron 1 has material id -1");
  // Every material is validated, naming it.
  EXPECT_PRED2(
      contains, message_of([&] {
        MaterialMap::per_tet({brain(), Material{2.0e5, 0.5, "artery"}}, {0, 1}).validate(2);
      }),
      "material 'artery'");
  // One mesh, one element: the nodal terms of anp-tet span the materials.
  Material anp = artery;
  anp.element = Element::kAnpTet;
  const std::string e = message_of([&] {
    MaterialMap::per_tet({brain(), anp}, {0, 1}).validate(2);
  });
  EXPECT_PRED2(contains, e, "material 'artery' asks for element 'anp-tet'");
  EXPECT_PRED2(contains, e, "material 'brain' for 'linear-tet'");
}

}  // namespace
}  // namespace neurosim::fem
