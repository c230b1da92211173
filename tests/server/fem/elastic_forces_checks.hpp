// Checks shared by the element tests (elastic_forces_test, equilibrium_solver_test,
// nodal_pressure_test): an element's forces against central differences of its energy, its
// tangent against central differences of its forces, its equilibrium under a tiny load against
// the linear StaticSolver, and inverted elements recovering when released.
#pragma once

#include "fem_test_meshes.hpp"
#include "server/fem/elastic_forces.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/static_solver.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <functional>
#include <initializer_list>
#include <string>

namespace neurosim::fem::testing {

// f[dof] = dE/du[dof] (central differences, h = 1e-8 m) at a few dofs, the last one included.
inline void expect_force_is_energy_gradient(const ElasticForces& forces, const Eigen::VectorXd& u,
                                            const std::string& what) {
  Eigen::VectorXd f;
  forces.internal_force(u, f);
  const double h = 1e-8;
  for (int dof : {0, 17, 40, 101, static_cast<int>(u.size()) - 1}) {
    Eigen::VectorXd up = u, um = u;
    up[dof] += h;
    um[dof] -= h;
    const double fd = (forces.energy(up) - forces.energy(um)) / (2.0 * h);
    EXPECT_NEAR(fd, f[dof], 1e-6 * f.cwiseAbs().maxCoeff()) << what << " dof " << dof;
  }
}

// K(:, dof) = df/du[dof] (central differences, h = 1e-8 m) for a few dofs; kd = the tangent at u.
inline void expect_tangent_is_force_derivative(const ElasticForces& forces,
                                               const Eigen::VectorXd& u, const Eigen::MatrixXd& kd,
                                               const std::string& what) {
  const double h = 1e-8;
  for (int dof : {1, 30, 77, 150}) {
    Eigen::VectorXd up = u, um = u, fp, fm;
    up[dof] += h;
    um[dof] -= h;
    forces.internal_force(up, fp);
    forces.internal_force(um, fm);
    const Eigen::VectorXd fd = (fp - fm) / (2.0 * h);
    EXPECT_LT((fd - kd.col(dof)).cwiseAbs().maxCoeff(), 1e-6 * kd.col(dof).cwiseAbs().maxCoeff())
        << what << " dof " << dof;
  }
}

// The beam under a 1e-6 N tip load (deflection ~1e-8 of its length) in each tier: Newton's
// equilibrium equals the linear solve to 1e-6 (the linearization is consistent).
inline void expect_small_loads_agree_with_the_linear_solve(const MaterialMap& mats,
                                                           std::initializer_list<Tier> tiers,
                                                           const std::string& what) {
  const Beam b = beam();
  const Eigen::VectorXd f = b.tip_load(1e-6);
  const Eigen::VectorXd u_lin = StaticSolver(b.mesh, mats, b.fixed).solve(f);
  for (Tier tier : tiers) {
    EquilibriumSolver solver({&b.mesh, mats, tier, b.fixed, {}, {}});
    const EquilibriumResult r = solver.solve(f);
    const double rel = rel_max_diff(r.displacement_m, u_lin);
    std::printf("%s, small load, %s: max |u - u_linear| / max |u_linear| = %.2e\n", what.c_str(),
                tier_name(tier), rel);
    EXPECT_LT(rel, 1e-6) << what << " " << tier_name(tier);
  }
}

// The top centre node of a 20 mm cube (2 x 2 x 2 hexahedra, base fixed) pushed 15 mm down and
// held (the reaction resists: downwards), then started from a state where the tool has dragged
// the centre node 18 mm down, below the fixed base (inverted elements), and released: each tier
// returns to rest (|u| < 1e-9 m) for the material of each Poisson ratio.
inline void expect_inverted_elements_recover_when_released(
    const std::function<MaterialMap(double nu)>& material, std::initializer_list<double> nus,
    std::initializer_list<Tier> tiers, const std::string& what_element,
    const std::function<double(double nu)>& press_depth_m = [](double) { return 0.015; }) {
  const mesh::TetMesh m = box_mesh({2, 2, 2, {0, 0, 0}, {0.02, 0.02, 0.02}, 0.0, 1});
  const std::vector<int> fixed =
      nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const std::vector<int> pushed = nodes_where(m, [](const Eigen::Vector3d& p) {
    return (p - Eigen::Vector3d(0.01, 0.01, 0.02)).norm() < 1e-9;
  });
  const std::vector<int> centre = nodes_where(m, [](const Eigen::Vector3d& p) {
    return (p - Eigen::Vector3d(0.01, 0.01, 0.01)).norm() < 1e-9;
  });
  ASSERT_EQ(pushed.size(), 1u);
  ASSERT_EQ(centre.size(), 1u);
  for (double nu : nus) {
    const MaterialMap mats = material(nu);
    for (Tier tier : tiers) {
      const std::string what =
          what_element + ", " + tier_name(tier) + " nu " + std::to_string(nu);
      PrescribedDofs press{pushed, Eigen::Vector3d(0, 0, -press_depth_m(nu)), kAllComponents};
      EquilibriumSolver solver({&m, mats, tier, fixed, {press}, {}});
      const EquilibriumResult pressed = solver.solve({});
      ASSERT_TRUE(pressed.displacement_m.allFinite()) << what;
      ASSERT_TRUE(pressed.reaction_n.allFinite()) << what;
      // Reaction = force of the support (the tool) on the body: downwards, the tissue resists.
      EXPECT_LT(pressed.reaction_n[3 * pushed[0] + 2], 0.0) << what;
      Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(m.num_vertices()));
      u[3 * centre[0] + 2] = -0.018;
      ElasticForcesReport before;
      solver.forces().energy(u, &before);
      EXPECT_GT(before.inverted_elements, 0) << what;
      solver.set_prescribed_values(Eigen::VectorXd::Zero(3));  // released
      const NewtonIncrement inc = solver.solve_from({}, u);
      std::printf("%s: %d inverted elements released -> rest in %zu Newton iterations\n",
                  what.c_str(), before.inverted_elements, inc.residual_n.size() - 1);
      EXPECT_LT(u.cwiseAbs().maxCoeff(), 1e-9) << what;
    }
  }
}

}  // namespace neurosim::fem::testing
