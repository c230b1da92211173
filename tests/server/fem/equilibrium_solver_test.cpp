// Newton equilibrium in every tier: small loads agree with the linear StaticSolver (consistency
// of the linearization), the linear tier in one iteration, quadratic convergence at the end of
// a large-deflection solve, an element inverted by a prescribed push recovers when released,
// nothing turns NaN at nu = 0.499, bad input is refused; warm-started updates that reuse the
// factorization (NewtonOptions::reuse_factorization) reach full Newton's answer with fewer
// factorizations than iterations, on one mesh and on a tied pair; the tangent predictor
// (NewtonOptions::tangent_predictor) starts each increment nearer equilibrium and reaches the
// same answer in fewer iterations; with the refactorizations on another thread
// (NewtonOptions::background_refactorization, start_factorization) the updates reach the same
// answer; a tangent factor larger than EquilibriumDefinition::max_factor_bytes is refused at
// construction.
#include "server/fem/equilibrium_solver.hpp"

#include "elastic_forces_checks.hpp"
#include "fem_test_meshes.hpp"
#include "server/fem/static_solver.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::nodes_where;

const Tier kTiers[] = {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear};

using testing::Beam;
using testing::beam;

TEST(FemEquilibriumSolver, SmallLoadsAgreeWithTheLinearSolver) {
  testing::expect_small_loads_agree_with_the_linear_solve(
      MaterialMap::uniform({1.0e6, 0.4, "beam"}),
      {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear}, "linear-tet");
}

TEST(FemEquilibriumSolver, LinearTierConvergesInOneIterationPerIncrement) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  EquilibriumSolver solver({&b.mesh, mats, Tier::kLinear, b.fixed, {}, {}});
  NewtonOptions o;
  o.increments = 1;
  const EquilibriumResult r = solver.solve(b.tip_load(5.0), o);
  ASSERT_EQ(r.increments.size(), 1u);
  EXPECT_EQ(r.increments[0].residual_n.size(), 2u);  // initial residual, one step
}

TEST(FemEquilibriumSolver, LargeDeflectionConvergesQuadratically) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
    EquilibriumSolver solver({&b.mesh, mats, tier, b.fixed, {}, {}});
    const EquilibriumResult r = solver.solve(b.tip_load(8.0));
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
  testing::expect_inverted_elements_recover_when_released(
      [](double nu) { return MaterialMap::uniform({3000.0, nu, "brain"}); }, {0.45, 0.499},
      {Tier::kLinear, Tier::kCorotational, Tier::kNonlinear}, "linear-tet");
}

// Two boxes, B on top of A, B's bottom nodes tied to A's top nodes (weights 1, 0, 0), and the
// merged mesh (one box of the same tetrahedra, B's material above). Built in place: the tie
// holds a pointer to b.
struct TiedBoxes {
  static constexpr double e = 0.02;  // m
  const mesh::TetMesh a = box_mesh({2, 2, 2, {0, 0, 0}, {e, e, e}, 0.0, 1});
  const mesh::TetMesh b = box_mesh({2, 2, 2, {0, 0, e}, {e, e, 2 * e}, 0.0, 1});
  const mesh::TetMesh merged = box_mesh({2, 2, 4, {0, 0, 0}, {e, e, 2 * e}, 0.0, 1});
  const Material soft{3000.0, 0.45, "brain"}, stiff{30000.0, 0.4, "vessel"};
  MaterialMap merged_mats;
  TiedMeshDefinition tie;
  std::vector<int> fixed_a, fixed_m;
  int corner_b{-1}, corner_m{-1};  // B's top corner (e, e, 2e) in b and in merged

  static int node_at(const mesh::TetMesh& m, const Eigen::Vector3d& p) {
    const auto ids = nodes_where(m, [&](const Eigen::Vector3d& q) { return (q - p).norm() < 1e-12; });
    return ids.size() == 1 ? ids[0] : -1;
  }
  TiedBoxes() {
    std::vector<int> tet_material;
    for (const auto& t : merged.tets()) {
      double z = 0.0;
      for (int k = 0; k < 4; ++k) z += merged.vertices()[t[k]].z() / 4.0;
      tet_material.push_back(z > e ? 1 : 0);
    }
    merged_mats = MaterialMap::per_tet({soft, stiff}, tet_material);
    tie.mesh = &b;
    tie.materials = MaterialMap::uniform(stiff);
    for (int v : nodes_where(b, [&](const Eigen::Vector3d& p) { return p.z() < e + 1e-12; })) {
      tie.tied_nodes.push_back(v);
      const int host = node_at(a, b.vertices()[v]);  // checked by the tests (>= 0)
      tie.host_nodes.push_back({host, host, host});
      tie.weights.push_back({1.0, 0.0, 0.0});
    }
    fixed_a = nodes_where(a, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
    fixed_m = nodes_where(merged, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
    corner_b = node_at(b, {e, e, 2 * e});
    corner_m = node_at(merged, {e, e, 2 * e});
  }
  TiedBoxes(const TiedBoxes&) = delete;
  TiedBoxes& operator=(const TiedBoxes&) = delete;
  EquilibriumDefinition pair(Tier tier) const {
    return {&a, MaterialMap::uniform(soft), tier, fixed_a, {}, {tie}};
  }
};

// The tied pair must equal the merged mesh solved as one body, in every tier: the tie is
// eliminated exactly.
TEST(FemEquilibriumSolver, TiedMeshEqualsTheMergedMesh) {
  const TiedBoxes boxes;
  const mesh::TetMesh& a = boxes.a;
  const mesh::TetMesh& b = boxes.b;
  const mesh::TetMesh& merged = boxes.merged;
  ASSERT_FALSE(boxes.tie.tied_nodes.empty());
  for (const auto& h : boxes.tie.host_nodes) ASSERT_GE(h[0], 0);
  ASSERT_GE(boxes.corner_b, 0);
  ASSERT_GE(boxes.corner_m, 0);
  auto node_at = &TiedBoxes::node_at;
  // A sideways and downward push on B's top corner (large enough to be nonlinear).
  const Eigen::Vector3d push(0.02, 0.01, -0.05);  // N
  for (Tier tier : kTiers) {
    EquilibriumSolver pair(boxes.pair(tier));
    Eigen::VectorXd f = Eigen::VectorXd::Zero(pair.num_dofs());
    f.segment<3>(pair.body_offset(1) + 3 * boxes.corner_b) = push;
    const EquilibriumResult rp = pair.solve(f);
    EquilibriumSolver one({&merged, boxes.merged_mats, tier, boxes.fixed_m, {}, {}});
    Eigen::VectorXd fm = Eigen::VectorXd::Zero(3 * merged.num_vertices());
    fm.segment<3>(3 * boxes.corner_m) = push;
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
    for (int v : boxes.fixed_a) {
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

// What a worker does: solve_from again and again, warm-started from the previous answer, for a
// load that changes a little between calls (here by 1-4 % in size and turning). Two solvers
// side by side from the same first equilibrium: full Newton and reuse_factorization. Each
// update must reach full Newton's answer (both converged to the same tolerance), and the
// reusing solver must actually reuse: fewer factorizations than iterations over the sequence
// (full Newton: at least one per iteration), none at all in the linear tier (the tangent is
// constant, the first factor is exact). `make_load(k)` gives the k-th load (k = 0: the first).
template <typename MakeLoad>
void check_reuse_sequence(const EquilibriumDefinition& def, MakeLoad make_load, int updates,
                          const std::string& what) {
  EquilibriumSolver full(def), reuse(def);
  // Both converged answers are within what the tolerance allows of the exact one: 1e-10 (the
  // default) allows ~5e-10 relative in u here, so 1e-12 for a 1e-9 comparison with margin.
  NewtonOptions full_options;
  full_options.tolerance = 1e-12;
  NewtonOptions reuse_options = full_options;
  reuse_options.reuse_factorization = true;
  const Eigen::VectorXd f0 = make_load(0);
  const EquilibriumResult first = full.solve(f0, full_options);
  reuse.solve(f0, full_options);  // leaves its last factor, as the worker's first full solve
  Eigen::VectorXd u_full = first.displacement_m, u_reuse = first.displacement_m;
  int its_full = 0, facts_full = 0, its_reuse = 0, facts_reuse = 0;
  double worst = 0.0;
  for (int k = 1; k <= updates; ++k) {
    const Eigen::VectorXd f = make_load(k);
    const NewtonIncrement a = full.solve_from(f, u_full, full_options);
    const NewtonIncrement b = reuse.solve_from(f, u_reuse, reuse_options);
    its_full += static_cast<int>(a.residual_n.size()) - 1;
    facts_full += a.factorizations;
    its_reuse += static_cast<int>(b.residual_n.size()) - 1;
    facts_reuse += b.factorizations;
    ASSERT_TRUE(u_reuse.allFinite()) << what;
    const double rel = testing::rel_max_diff(u_reuse, u_full);
    worst = std::max(worst, rel);
    EXPECT_LT(rel, 1e-9) << what << " update " << k;
  }
  std::printf("%s: %d updates: full Newton %d iterations / %d factorizations, reuse %d / %d, "
              "max |u_reuse - u_full| / max |u_full| = %.2e\n",
              what.c_str(), updates, its_full, facts_full, its_reuse, facts_reuse, worst);
  EXPECT_GE(facts_full, its_full) << what;
  EXPECT_GT(its_reuse, 0) << what;
  EXPECT_LT(facts_reuse, its_reuse) << what;
  if (def.tier == Tier::kLinear) {
    EXPECT_EQ(facts_reuse, 0) << what;
  }
}

// A loose load path (path_tolerance) with chord steps (reuse_factorization), as neurosim-solve
// runs it: the increments before the last stop early, fewer tangents are factorized, and the
// answer at load factor 1 is full Newton's to the convergence tolerance.
TEST(FemEquilibriumSolver, LoosePathWithChordStepsReachesFullNewtonsAnswer) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  const Eigen::VectorXd f = b.tip_load(8.0);
  for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
    NewtonOptions full;
    full.increments = 4;
    EquilibriumSolver a({&b.mesh, mats, tier, b.fixed, {}, {}});
    const EquilibriumResult ra = a.solve(f, full);
    NewtonOptions loose = full;
    loose.path_tolerance = 1e-4;
    loose.reuse_factorization = true;
    EquilibriumSolver c({&b.mesh, mats, tier, b.fixed, {}, {}});
    const EquilibriumResult rc = c.solve(f, loose);
    int fa = 0, fc = 0;
    for (const auto& inc : ra.increments) fa += inc.factorizations;
    for (const auto& inc : rc.increments) fc += inc.factorizations;
    ASSERT_EQ(ra.increments.size(), rc.increments.size()) << tier_name(tier);
    for (std::size_t i = 0; i + 1 < rc.increments.size(); ++i) {
      EXPECT_GT(rc.increments[i].residual_n.back(), 1e-10 * rc.force_scale_n)
          << tier_name(tier) << " increment " << i << " stopped at the path tolerance";
      EXPECT_LE(rc.increments[i].residual_n.back(), 1e-4 * 1.5 * rc.force_scale_n);
    }
    EXPECT_LE(rc.increments.back().residual_n.back(), 1e-10 * rc.force_scale_n);
    const double rel = testing::rel_max_diff(rc.displacement_m, ra.displacement_m);
    std::printf("%s: loose path + chords %d factorizations, full Newton %d; rel diff %.2e\n",
                tier_name(tier), fc, fa, rel);
    EXPECT_LT(fc, fa) << tier_name(tier);
    EXPECT_LT(rel, 1e-8) << tier_name(tier);
  }
}

// The tangent predictor (NewtonOptions::tangent_predictor) on a press like neurosim-solve's: a
// 2 cm block fixed at the bottom, the top's middle node and its neighbours pushed 6 mm down in
// 4 increments. Without it each increment starts by crushing the layer of elements under the
// pushed nodes; with it every increment starts from the predicted u, needs fewer iterations,
// and the answer at load factor 1 is the same to the convergence tolerance. Also on a tied pair
// under a force (K_fc dc = 0 there: the predictor is K_ff^-1 of the force's increment).
TEST(FemEquilibriumSolver, TangentPredictorReachesTheSameAnswerInFewerIterations) {
  const double e = 0.02;
  const mesh::TetMesh m = box_mesh({4, 4, 4, {0, 0, 0}, {e, e, e}, 0.2, 3});
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const std::vector<int> fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  PrescribedDofs press;
  press.nodes = nodes_where(m, [&](const Eigen::Vector3d& p) {
    return p.z() > e - 1e-12 && std::abs(p.x() - e / 2) < 0.3 * e && std::abs(p.y() - e / 2) < 0.3 * e;
  });
  ASSERT_EQ(press.nodes.size(), 9u);
  press.displacement_m = Eigen::Vector3d(0.0, 0.0, -0.006);
  auto iterations = [](const EquilibriumResult& r) {
    int n = 0;
    for (const auto& inc : r.increments) n += static_cast<int>(inc.residual_n.size()) - 1;
    return n;
  };
  for (bool offline : {false, true}) {  // full Newton; neurosim-solve's chords and loose path
    NewtonOptions plain;
    plain.increments = 4;
    plain.reuse_factorization = offline;
    plain.path_tolerance = offline ? 1e-4 : 0.0;
    NewtonOptions predicted = plain;
    predicted.tangent_predictor = true;
    EquilibriumSolver a({&m, mats, Tier::kNonlinear, fixed, {press}, {}});
    const EquilibriumResult ra = a.solve(Eigen::VectorXd(), plain);
    EquilibriumSolver c({&m, mats, Tier::kNonlinear, fixed, {press}, {}});
    const EquilibriumResult rc = c.solve(Eigen::VectorXd(), predicted);
    ASSERT_EQ(rc.increments.size(), 4u);
    for (const auto& inc : ra.increments) EXPECT_FALSE(inc.predicted);
    for (std::size_t i = 0; i < rc.increments.size(); ++i) {
      EXPECT_TRUE(rc.increments[i].predicted) << "increment " << i;
      // The predicted start is nearer equilibrium than the plain one.
      EXPECT_LT(rc.increments[i].residual_n.front(),
                0.5 * ra.increments[std::min(i, ra.increments.size() - 1)].residual_n.front())
          << "increment " << i;
    }
    EXPECT_LE(rc.increments.back().residual_n.back(), 1e-10 * rc.force_scale_n);
    const double rel = testing::rel_max_diff(rc.displacement_m, ra.displacement_m);
    double reaction = 0.0, reaction_diff = 0.0;
    for (int v : press.nodes) {
      reaction = std::max(reaction, ra.reaction_n.segment<3>(3 * v).norm());
      reaction_diff = std::max(reaction_diff,
                               (rc.reaction_n.segment<3>(3 * v) - ra.reaction_n.segment<3>(3 * v)).norm());
    }
    std::printf("press %s: %d iterations with the predictor, %d without; rel diff %.2e, "
                "reactions %.2e\n",
                offline ? "(chords, loose path)" : "(full Newton)", iterations(rc), iterations(ra),
                rel, reaction_diff / reaction);
    EXPECT_LT(iterations(rc), iterations(ra));
    EXPECT_LT(rel, 1e-8);
    EXPECT_LT(reaction_diff, 1e-8 * reaction);
  }

  const TiedBoxes boxes;
  const EquilibriumDefinition def = boxes.pair(Tier::kNonlinear);
  EquilibriumSolver pair(def), pair_predicted(def);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(pair.num_dofs());
  f.segment<3>(pair.body_offset(1) + 3 * boxes.corner_b) = Eigen::Vector3d(0.02, 0.01, -0.05);
  NewtonOptions plain;
  plain.increments = 4;
  NewtonOptions predicted = plain;
  predicted.tangent_predictor = true;
  const EquilibriumResult rp = pair.solve(f, plain);
  const EquilibriumResult rq = pair_predicted.solve(f, predicted);
  for (const auto& inc : rq.increments) EXPECT_TRUE(inc.predicted);
  const double rel = testing::rel_max_diff(rq.displacement_m, rp.displacement_m);
  std::printf("tied pair: %d iterations with the predictor, %d without; rel diff %.2e\n",
              iterations(rq), iterations(rp), rel);
  EXPECT_LE(iterations(rq), iterations(rp));
  EXPECT_LT(rel, 1e-8);
}

// 4 N at the beam's tip growing 3 % per update k and turning sideways: a large deflection
// (~40 % of the length in the nonlinear tiers) that moves at every update.
Eigen::VectorXd growing_tip_load(const Beam& b, int k) {
  Eigen::VectorXd f = b.tip_load(4.0 * (1.0 + 0.03 * k));
  for (int v : b.tip) f[3 * v + 1] = 0.02 * k * f[3 * v + 2];
  return f;
}

TEST(FemEquilibriumSolver, ReusedFactorizationReachesFullNewtonsAnswer) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  auto load = [&](int k) { return growing_tip_load(b, k); };
  for (Tier tier : kTiers) {
    check_reuse_sequence({&b.mesh, mats, tier, b.fixed, {}, {}}, load, 6,
                         std::string("beam ") + tier_name(tier));
  }
}

TEST(FemEquilibriumSolver, ReusedFactorizationOnATiedPair) {
  const TiedBoxes boxes;
  for (const auto& h : boxes.tie.host_nodes) ASSERT_GE(h[0], 0);
  ASSERT_GE(boxes.corner_b, 0);
  for (Tier tier : kTiers) {
    const EquilibriumDefinition def = boxes.pair(tier);
    const int ndof = EquilibriumSolver(def).num_dofs();
    const int corner = 3 * (static_cast<int>(boxes.a.num_vertices()) + boxes.corner_b);
    auto load = [&](int k) {
      Eigen::VectorXd f = Eigen::VectorXd::Zero(ndof);
      f.segment<3>(corner) = Eigen::Vector3d(0.02, 0.01 + 0.001 * k, -0.05 * (1.0 + 0.02 * k));
      return f;
    };
    check_reuse_sequence(def, load, 6, std::string("tied pair ") + tier_name(tier));
  }
}

// The worker's loop again, with the refactorizations on another thread
// (NewtonOptions::background_refactorization) and the first factor made ahead
// (start_factorization, at rest): each update reaches full Newton's answer. Which iterations
// take a background factor depends on the threads' timing; what does not: the first solve
// steps with the factor made ahead (waited for, none of its own), and the first refactorization
// the contraction asks for is started in the background (a call without the option takes it:
// some factor was adopted).
TEST(FemEquilibriumSolver, BackgroundRefactorizationReachesFullNewtonsAnswer) {
  const Beam b = beam();
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "beam"});
  auto load = [&](int k) { return growing_tip_load(b, k); };
  for (Tier tier : {Tier::kCorotational, Tier::kNonlinear}) {
    const EquilibriumDefinition def{&b.mesh, mats, tier, b.fixed, {}, {}};
    const std::string what = std::string("beam ") + tier_name(tier);
    EquilibriumSolver full(def), background(def);
    NewtonOptions full_options;
    full_options.tolerance = 1e-12;
    NewtonOptions options = full_options;
    options.reuse_factorization = true;
    options.background_refactorization = true;
    ASSERT_TRUE(background.start_factorization(Eigen::VectorXd::Zero(background.num_dofs())));
    EXPECT_FALSE(background.start_factorization(Eigen::VectorXd::Zero(background.num_dofs())))
        << "one at a time";
    const EquilibriumResult first_full = full.solve(load(0), full_options);
    const EquilibriumResult first = background.solve(load(0), options);
    ASSERT_FALSE(first.increments.empty());
    EXPECT_GE(first.increments[0].adopted_factorizations, 1) << what;  // the one made ahead
    EXPECT_LT(testing::rel_max_diff(first.displacement_m, first_full.displacement_m), 1e-9) << what;
    Eigen::VectorXd u_full = first_full.displacement_m, u_bg = first.displacement_m;
    int adopted = 0, own = 0, its = 0;
    for (int k = 1; k <= 6; ++k) {
      const Eigen::VectorXd f = load(k);
      full.solve_from(f, u_full, full_options);
      const NewtonIncrement inc = background.solve_from(f, u_bg, options);
      adopted += inc.adopted_factorizations;
      own += inc.factorizations;
      its += static_cast<int>(inc.residual_n.size()) - 1;
      ASSERT_TRUE(u_bg.allFinite()) << what;
      EXPECT_LT(testing::rel_max_diff(u_bg, u_full), 1e-9) << what << " update " << k;
    }
    // In line from here: a factorization still running is waited for and taken.
    NewtonOptions in_line = options;
    in_line.background_refactorization = false;
    const NewtonIncrement last = background.solve_from(load(6), u_bg, in_line);
    adopted += last.adopted_factorizations;
    EXPECT_LT(testing::rel_max_diff(u_bg, u_full), 1e-9) << what;
    std::printf("%s: 6 updates, %d iterations, %d factorizations in line, %d taken from the "
                "background\n", what.c_str(), its, own, adopted);
    EXPECT_GE(adopted, 1) << what;
  }
}

// The tangent's factor is refused at construction when it needs more than max_factor_bytes,
// with its size from the symbolic analysis: the size StaticSolver's factor of the same mesh,
// supports and ordering has (the same pattern), and the one just enough for it is taken.
TEST(FemEquilibriumSolver, FactorLargerThanTheMemoryLimitIsRefusedWithTheEstimate) {
  const mesh::TetMesh m = box_mesh({6, 6, 6, {0, 0, 0}, {0.06, 0.06, 0.06}, 0.0, 1});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const double bytes = static_cast<double>(StaticSolver(m, mats, fixed).factor_info().factor_bytes);
  ASSERT_GT(bytes, 0.0);
  EquilibriumDefinition d{&m, mats, Tier::kNonlinear, fixed, {}, {}};
  EXPECT_NO_THROW(EquilibriumSolver{d});  // the default limit: the machine's available memory
  d.max_factor_bytes = 0.5 * bytes;
  try {
    EquilibriumSolver refused(d);
    FAIL() << "a factor of " << bytes << " bytes was not refused at a limit of half of it";
  } catch (const FactorTooLarge& e) {
    EXPECT_DOUBLE_EQ(e.needed_bytes, bytes);
    EXPECT_DOUBLE_EQ(e.available_bytes, 0.5 * bytes);
    const std::string what = e.what();
    EXPECT_NE(what.find("MiB"), std::string::npos) << what;
    EXPECT_NE(what.find("max_factor_bytes"), std::string::npos) << what;
  }
  d.max_factor_bytes = bytes;  // exactly enough: it factorizes and solves
  EquilibriumSolver enough(d);
  const Eigen::VectorXd f = Eigen::VectorXd::Constant(enough.num_dofs(), 1e-4);
  EXPECT_TRUE(enough.solve(f).displacement_m.allFinite());
  d.max_factor_bytes = -1.0;
  EXPECT_THROW(EquilibriumSolver{d}, std::invalid_argument);
}

TEST(FemEquilibriumSolver, RefusesBadInput) {
  const mesh::TetMesh m = box_mesh({1, 1, 1, {0, 0, 0}, {0.01, 0.01, 0.01}, 0.0, 1});
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const std::string free_body = neurosim::testing::message_of(
      [&] { EquilibriumSolver({&m, mats, Tier::kNonlinear, {}, {}, {}}); });
  EXPECT_NE(free_body.find("rigid body"), std::string::npos) << free_body;
  const std::string bad_node = neurosim::testing::message_of(
      [&] { EquilibriumSolver({&m, mats, Tier::kNonlinear, {99}, {}, {}}); });
  EXPECT_NE(bad_node.find("fixed node 99"), std::string::npos) << bad_node;
  EquilibriumSolver solver({&m, mats, Tier::kNonlinear, {0, 1, 2, 3}, {}, {}});
  EXPECT_THROW(solver.solve(Eigen::VectorXd::Zero(2)), std::invalid_argument);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * m.num_vertices());
  f[20] = std::nan("");
  EXPECT_THROW(solver.solve(f), std::invalid_argument);
  NewtonOptions reuse;
  reuse.reuse_factorization = true;
  reuse.refactor_contraction = 1.0;  // would never refactorize
  Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * m.num_vertices());
  const std::string bad_option = neurosim::testing::message_of(
      [&] { solver.solve_from(Eigen::VectorXd::Zero(u.size()), u, reuse); });
  EXPECT_NE(bad_option.find("refactor_contraction 1"), std::string::npos) << bad_option;
  reuse.refactor_contraction = 0.5;
  reuse.anderson_depth = -1;
  EXPECT_THROW(solver.solve(Eigen::VectorXd::Zero(u.size()), reuse), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::fem
