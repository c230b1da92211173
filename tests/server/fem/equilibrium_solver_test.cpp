// Newton equilibrium in every tier: small loads agree with the linear StaticSolver (consistency
// of the linearization), the linear tier in one iteration, quadratic convergence at the end of
// a large-deflection solve, an element inverted by a prescribed push recovers when released,
// nothing turns NaN at nu = 0.499, bad input is refused.
#include "server/fem/equilibrium_solver.hpp"

#include "fem_test_meshes.hpp"
#include "server/fem/static_solver.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::nodes_where;

const Tier kTiers[] = {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear};

struct Beam {
  mesh::TetMesh mesh;
  std::vector<int> fixed;
  std::vector<int> tip;
};

Beam beam() {
  Beam b{box_mesh({10, 2, 2, {0, 0, 0}, {0.1, 0.02, 0.02}, 0.0, 1}), {}, {}};
  b.fixed = nodes_where(b.mesh, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  b.tip = nodes_where(b.mesh, [](const Eigen::Vector3d& p) { return p.x() > 0.1 - 1e-9; });
  return b;
}

Eigen::VectorXd tip_load(const Beam& b, double total_n) {
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * b.mesh.num_vertices());
  for (int v : b.tip) f[3 * v + 2] = -total_n / static_cast<double>(b.tip.size());
  return f;
}

TEST(FemEquilibriumSolver, SmallLoadsAgreeWithTheLinearSolver) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  const Eigen::VectorXd f = tip_load(b, 1e-6);  // tip deflection ~1e-8 of the length
  const StaticSolver linear(b.mesh, mats, b.fixed);
  const Eigen::VectorXd u_lin = linear.solve(f);
  for (Tier tier : kTiers) {
    EquilibriumSolver solver({&b.mesh, mats, tier, b.fixed, {}});
    const EquilibriumResult r = solver.solve(f);
    const double rel = testing::rel_max_diff(r.displacement_m, u_lin);
    std::printf("small load, %s tier: max |u - u_linear| / max |u_linear| = %.2e\n",
                tier_name(tier), rel);
    EXPECT_LT(rel, 1e-6) << tier_name(tier);
  }
}

TEST(FemEquilibriumSolver, LinearTierConvergesInOneIterationPerIncrement) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  EquilibriumSolver solver({&b.mesh, mats, Tier::kLinear, b.fixed, {}});
  NewtonOptions o;
  o.increments = 1;
  const EquilibriumResult r = solver.solve(tip_load(b, 5.0), o);
  ASSERT_EQ(r.increments.size(), 1u);
  EXPECT_EQ(r.increments[0].residual_n.size(), 2u);  // initial residual, one step
}

TEST(FemEquilibriumSolver, LargeDeflectionConvergesQuadratically) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
    EquilibriumSolver solver({&b.mesh, mats, tier, b.fixed, {}});
    const EquilibriumResult r = solver.solve(tip_load(b, 8.0));
    double tip_w = 0.0;
    for (int v : b.tip) tip_w = std::min(tip_w, r.displacement_m[3 * v + 2]);
    std::printf("%s: tip deflection %.4f m (%.0f %% of the length), %zu increments\n",
                tier_name(tier), -tip_w, -tip_w / 0.1 * 100.0, r.increments.size());
    EXPECT_GT(-tip_w, 0.2 * 0.1) << tier_name(tier);
    ASSERT_TRUE(r.displacement_m.allFinite());
    const std::vector<double>& res = r.increments.back().residual_n;
    ASSERT_GE(res.size(), 3u);
    EXPECT_LE(res.back(), 1e-10 * r.force_scale_n);
    // Quadratic at the end (exact tangent): the last reduction is far beyond a linear rate.
    const std::size_t n = res.size();
    EXPECT_LT(res[n - 1] / res[n - 2], 1e-2) << tier_name(tier);
    EXPECT_EQ(r.elements.clamped_elements, 0);
  }
}

TEST(FemEquilibriumSolver, InvertedElementRecoversWhenReleased) {
  // The top centre node of a small cube pushed 15 mm down into its 20 mm height: held there,
  // then started from a state where the tool has dragged it through the layer below (its
  // elements inverted) and released.
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
  for (double nu : {0.45, 0.499}) {
    const MaterialMap mats = MaterialMap::uniform({3000.0, nu, "brain"});
    for (Tier tier : kTiers) {
      const std::string what = std::string(tier_name(tier)) + " nu " + std::to_string(nu);
      PrescribedDofs press{pushed, Eigen::Vector3d(0, 0, -0.015), kAllComponents};
      EquilibriumSolver solver({&m, mats, tier, fixed, {press}});
      const EquilibriumResult pressed = solver.solve({});
      ASSERT_TRUE(pressed.displacement_m.allFinite()) << what;
      ASSERT_TRUE(pressed.reaction_n.allFinite()) << what;
      // Reaction = force of the support (the tool) on the body: downwards, the tissue resists.
      EXPECT_LT(pressed.reaction_n[3 * pushed[0] + 2], 0.0) << what;

      // Dragged through: the centre node 18 mm down, below the fixed base (inverted elements).
      Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * m.num_vertices());
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

// Two boxes, B on top of A, B's bottom nodes tied to A's top nodes (weights 1, 0, 0): the tied
// pair must equal the merged mesh (one box of the same tetrahedra, B's material above) solved
// as one body, in every tier: the tie is eliminated exactly.
TEST(FemEquilibriumSolver, TiedMeshEqualsTheMergedMesh) {
  const double e = 0.02;  // m
  const mesh::TetMesh a = box_mesh({2, 2, 2, {0, 0, 0}, {e, e, e}, 0.0, 1});
  const mesh::TetMesh b = box_mesh({2, 2, 2, {0, 0, e}, {e, e, 2 * e}, 0.0, 1});
  const mesh::TetMesh merged = box_mesh({2, 2, 4, {0, 0, 0}, {e, e, 2 * e}, 0.0, 1});
  const Material soft{3000.0, 0.45, "brain"}, stiff{30000.0, 0.4, "vessel"};
  std::vector<int> tet_material;
  for (const auto& t : merged.tets()) {
    double z = 0.0;
    for (int k = 0; k < 4; ++k) z += merged.vertices()[t[k]].z() / 4.0;
    tet_material.push_back(z > e ? 1 : 0);
  }
  const MaterialMap merged_mats = MaterialMap::per_tet({soft, stiff}, tet_material);
  auto node_at = [](const mesh::TetMesh& m, const Eigen::Vector3d& p) {
    const auto ids = nodes_where(m, [&](const Eigen::Vector3d& q) { return (q - p).norm() < 1e-12; });
    return ids.size() == 1 ? ids[0] : -1;
  };
  TiedMeshDefinition tie;
  tie.mesh = &b;
  tie.materials = MaterialMap::uniform(stiff);
  for (int v : nodes_where(b, [&](const Eigen::Vector3d& p) { return p.z() < e + 1e-12; })) {
    const int host = node_at(a, b.vertices()[v]);
    ASSERT_GE(host, 0);
    tie.tied_nodes.push_back(v);
    tie.host_nodes.push_back({host, host, host});
    tie.weights.push_back({1.0, 0.0, 0.0});
  }
  const std::vector<int> fixed_a = nodes_where(a, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  const std::vector<int> fixed_m =
      nodes_where(merged, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  // A sideways and downward push on B's top corner (large enough to be nonlinear).
  const Eigen::Vector3d push(0.02, 0.01, -0.05);  // N
  const int corner_b = node_at(b, {e, e, 2 * e}), corner_m = node_at(merged, {e, e, 2 * e});
  for (Tier tier : kTiers) {
    EquilibriumDefinition def{&a, MaterialMap::uniform(soft), tier, fixed_a, {}, {tie}};
    EquilibriumSolver pair(def);
    Eigen::VectorXd f = Eigen::VectorXd::Zero(pair.num_dofs());
    f.segment<3>(pair.body_offset(1) + 3 * corner_b) = push;
    const EquilibriumResult rp = pair.solve(f);
    EquilibriumSolver one({&merged, merged_mats, tier, fixed_m, {}});
    Eigen::VectorXd fm = Eigen::VectorXd::Zero(3 * merged.num_vertices());
    fm.segment<3>(3 * corner_m) = push;
    const EquilibriumResult rm = one.solve(fm);
    double diff = 0.0, rdiff = 0.0;
    for (int body = 0; body < 2; ++body) {
      const mesh::TetMesh& mb = body == 0 ? a : b;
      for (std::size_t v = 0; v < mb.num_vertices(); ++v) {
        const int w = node_at(merged, mb.vertices()[v]);
        ASSERT_GE(w, 0);
        diff = std::max(diff, (rp.displacement_m.segment<3>(pair.body_offset(body) + 3 * v) -
                               rm.displacement_m.segment<3>(3 * w))
                                  .cwiseAbs()
                                  .maxCoeff());
      }
    }
    for (int v : fixed_a) {
      rdiff = std::max(rdiff, (rp.reaction_n.segment<3>(3 * v) -
                               rm.reaction_n.segment<3>(3 * node_at(merged, a.vertices()[v])))
                                  .cwiseAbs()
                                  .maxCoeff());
    }
    const double max_u = rm.displacement_m.cwiseAbs().maxCoeff();
    std::printf("%s: tied pair vs merged mesh: max |du| / max |u| = %.2e (max |u| %.2e m), "
                "reactions %.2e N\n",
                tier_name(tier), diff / max_u, max_u, rdiff);
    EXPECT_GT(max_u, 1e-3) << tier_name(tier);
    EXPECT_LT(diff, 1e-9 * max_u) << tier_name(tier);
    EXPECT_LT(rdiff, 1e-9 * push.norm()) << tier_name(tier);
  }
}

TEST(FemEquilibriumSolver, RefusesBadInput) {
  const mesh::TetMesh m = box_mesh({1, 1, 1, {0, 0, 0}, {0.01, 0.01, 0.01}, 0.0, 1});
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const std::string free_body = neurosim::testing::message_of(
      [&] { EquilibriumSolver({&m, mats, Tier::kNonlinear, {}, {}}); });
  EXPECT_NE(free_body.find("rigid body"), std::string::npos) << free_body;
  const std::string bad_node = neurosim::testing::message_of(
      [&] { EquilibriumSolver({&m, mats, Tier::kNonlinear, {99}, {}}); });
  EXPECT_NE(bad_node.find("fixed node 99"), std::string::npos) << bad_node;
  EquilibriumSolver solver({&m, mats, Tier::kNonlinear, {0, 1, 2, 3}, {}});
  EXPECT_THROW(solver.solve(Eigen::VectorXd::Zero(2)), std::invalid_argument);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * m.num_vertices());
  f[20] = std::nan("");
  EXPECT_THROW(solver.solve(f), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
