// Element forces of each tier on a mesh: forces are the gradient of the energy and the tangent
// the derivative of the forces (finite differences); the linear tier reproduces the assembled
// K u; a rigid 90 degree rotation of the cube leaves no residual force in the corotational and
// nonlinear tiers while the linear tier sees the full stiffness force.
#include "server/fem/elastic_forces.hpp"

#include "elastic_forces_checks.hpp"
#include "fem_test_meshes.hpp"
#include "server/fem/assembly.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cstdio>

namespace neurosim::fem {
namespace {

using testing::random_displacement;

const Tier kTiers[] = {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear};

mesh::TetMesh cube() {
  return testing::box_mesh({3, 3, 3, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 7});
}

TEST(FemElasticForces, ForceIsTheGradientOfTheEnergy) {
  const mesh::TetMesh m = cube();
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const Eigen::VectorXd u = random_displacement(m, 4e-3, 3);
  for (Tier tier : kTiers)
    testing::expect_force_is_energy_gradient(ElasticForces(m, mats, tier), u, tier_name(tier));
}

TEST(FemElasticForces, TangentIsTheDerivativeOfTheForce) {
  const mesh::TetMesh m = cube();
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const Eigen::VectorXd u = random_displacement(m, 4e-3, 5);
  for (Tier tier : kTiers) {
    const ElasticForces forces(m, mats, tier);
    SparseMatrix k;
    forces.tangent(u, false, k);
    testing::expect_tangent_is_force_derivative(forces, u, Eigen::MatrixXd(k), tier_name(tier));
  }
}

TEST(FemElasticForces, LinearTierIsTheAssembledStiffness) {
  const mesh::TetMesh m = cube();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "cube"});
  const Eigen::VectorXd u = random_displacement(m, 1e-3, 9);
  const ElasticForces forces(m, mats, Tier::kLinear);
  Eigen::VectorXd f;
  forces.internal_force(u, f);
  const Eigen::VectorXd ku = assemble_stiffness(m, mats) * u;
  EXPECT_LT((f - ku).cwiseAbs().maxCoeff(), 1e-12 * ku.cwiseAbs().maxCoeff());
  SparseMatrix k;
  forces.tangent(u, false, k);
  EXPECT_LT((Eigen::MatrixXd(k) - Eigen::MatrixXd(assemble_stiffness(m, mats))).cwiseAbs().maxCoeff(),
            1e-12 * Eigen::MatrixXd(k).cwiseAbs().maxCoeff());
}

TEST(FemElasticForces, RigidRotationLeavesNoResidualForce) {
  const mesh::TetMesh m = cube();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "cube"});
  const Eigen::Matrix3d r = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d(1, 1, 0).normalized()).matrix();
  const Eigen::Vector3d c(0.05, 0.05, 0.05);
  Eigen::VectorXd u(3 * m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    const Eigen::Vector3d x = m.vertices()[v];
    u.segment<3>(3 * v) = (r * (x - c) + c) - x;
  }
  // Stiffness scale: the force the linear stiffness gives this displacement.
  const double scale = (assemble_stiffness(m, mats) * u).cwiseAbs().maxCoeff();
  for (Tier tier : kTiers) {
    const ElasticForces forces(m, mats, tier);
    Eigen::VectorXd f;
    ElasticForcesReport report;
    forces.internal_force(u, f, &report);
    const double rel = f.cwiseAbs().maxCoeff() / scale;
    std::printf("rigid 90 deg rotation, %s tier: max |f_int| / max |K u| = %.3e\n", tier_name(tier),
                rel);
    if (tier == Tier::kLinear) {
      EXPECT_GT(rel, 0.5);  // linear elasticity sees the rotation as a large strain
    } else {
      EXPECT_LT(rel, 1e-9) << tier_name(tier);
      EXPECT_LT(report.max_strain, 1e-12) << tier_name(tier);
    }
  }
}

TEST(FemElasticForces, RefusesAWrongSize) {
  const mesh::TetMesh m = cube();
  const ElasticForces forces(m, MaterialMap::uniform({3000.0, 0.45, "brain"}), Tier::kNonlinear);
  Eigen::VectorXd f;
  EXPECT_THROW(forces.internal_force(Eigen::VectorXd::Zero(5), f), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
