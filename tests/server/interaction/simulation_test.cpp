// Simulation on a small cube/cylinder scene: exact tie, paper Figures 10 and 14, contact force
// against in-process references (StaticSolver, monolithic KKT system), stiffness, unilaterality.
#include "server/interaction/simulation.hpp"

#include "interaction_fixtures.hpp"
#include "server/fem/assembly.hpp"
#include "server/fem/static_solver.hpp"
#include "server/fusion/coupling_map.hpp"
#include "server/fusion/inclusion.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>
#include <Eigen/SparseLU>

#include <cmath>
#include <filesystem>

namespace neurosim::interaction {
namespace {

using testing::SceneSpec;

using testing::push_right;
using testing::run;
using testing::Stepped;

void expect_sane(const Stepped& s, double bound_n) {
  for (const auto& c : s.contacts) {
    EXPECT_TRUE(c.force_n.allFinite());
    EXPECT_TRUE(c.stiffness_n_per_m.allFinite());
    EXPECT_LE(c.force_n.norm(), bound_n);
    // The tool pushes: the force on it points out of the tissue, along its contact normal.
    if (c.in_contact) {
      EXPECT_GE(c.force_n.dot(c.normal), 0.0);
    }
  }
  for (int m = 0; m < s.sim->num_meshes(); ++m) {
    Eigen::VectorXd u;
    s.sim->displacements(m, u);
    EXPECT_TRUE(u.allFinite()) << "mesh " << m;
  }
}

TEST(interaction_simulation, ExactTieResidual) {
  const double depth = 0.005;
  auto s = run(SceneSpec{}, {push_right(depth)});
  ASSERT_TRUE(s.stats.converged);
  ASSERT_TRUE(s.contacts[0].in_contact);
  EXPECT_GT(s.contacts[0].force_n.x(), 0.0);
  EXPECT_GT(s.sim->setup_stats().tied_nodes, 0);
  EXPECT_LE(s.sim->tie_residual_m(), 1e-9 * depth);
}

TEST(interaction_simulation, Figure10CylinderMovesOnlyWithCoupling) {
  const double depth = 0.005;
  SceneSpec off;
  off.coupling = false;
  auto a = run(off, {push_right(depth)});
  auto b = run(SceneSpec{}, {push_right(depth)});
  const int cyl = 1;
  ASSERT_EQ(a.sim->mesh_id(cyl), "cylinder");
  EXPECT_FALSE(a.sim->mesh_active(cyl));
  EXPECT_TRUE(b.sim->mesh_active(cyl));
  Eigen::VectorXd ua, ub;
  a.sim->displacements(cyl, ua);
  b.sim->displacements(cyl, ub);
  EXPECT_EQ(ua.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_GT(ub.cwiseAbs().maxCoeff(), 0.01 * depth);
  // The cylinder moves the way the cube is pushed (towards -x).
  double mean_x = 0.0;
  for (int v = 0; v < ub.size() / 3; ++v) mean_x += ub[3 * v];
  EXPECT_LT(mean_x, 0.0);
}

TEST(interaction_simulation, Figure14ForceDependsOnCoupling) {
  const double depth = 0.005;
  SceneSpec off;
  off.coupling = false;
  auto a = run(off, {push_right(depth)});
  auto b = run(SceneSpec{}, {push_right(depth)});
  SimulationOptions whole;
  whole.carve_host = false;
  auto c = run(SceneSpec{}, {push_right(depth)}, whole);
  ASSERT_TRUE(a.contacts[0].in_contact && b.contacts[0].in_contact && c.contacts[0].in_contact);
  EXPECT_GT(b.sim->setup_stats().carved_tets, 0);
  EXPECT_EQ(c.sim->setup_stats().carved_tets, 0);
  EXPECT_LT(b.sim->mesh(0).num_tets(), a.sim->mesh(0).num_tets());
  // The softer cylinder (0.1 MPa) replaces cube material (1 MPa) inside S': the cube is softer.
  EXPECT_LT(b.contacts[0].force_n.norm(), 0.999 * a.contacts[0].force_n.norm());
  // Without carving the tied cylinder only adds material: the cube is stiffer.
  EXPECT_GT(c.contacts[0].force_n.norm(), 1.0001 * a.contacts[0].force_n.norm());
}

TEST(interaction_simulation, ForceEqualsStaticSolverReaction) {
  SceneSpec spec;
  spec.coupling = false;
  auto s = run(spec, {push_right(0.004)});
  const auto& c = s.contacts[0];
  ASSERT_TRUE(c.in_contact);
  ASSERT_GE(c.nodes.size(), 1u);
  Eigen::VectorXd u;
  s.sim->displacements(0, u);
  // Reference: the same nodes prescribed to the displacements the contact produced.
  const auto scene = testing::make_scene(spec);
  const auto& m = s.sim->mesh(0);
  const auto& fixed = scene.meshes[0].fixed_nodes;
  fem::StaticSolver solver(m, fem::MaterialMap::uniform(scene.meshes[0].material), fixed);
  Eigen::VectorXd ud(3 * c.nodes.size());
  for (std::size_t k = 0; k < c.nodes.size(); ++k)
    ud.segment<3>(3 * k) = u.segment<3>(3 * c.nodes[k]);
  const auto ref = solver.solve_prescribed(c.nodes, ud);
  Vec3 support = Vec3::Zero();
  for (int v : c.nodes) support += ref.reaction_n.segment<3>(3 * v);
  // The supports push the nodes the way the tool does: the tool feels the opposite.
  EXPECT_LE((-support - c.force_n).norm(), 1e-9 * c.force_n.norm());
  EXPECT_LE((ref.displacement_m - u).cwiseAbs().maxCoeff(), 1e-9 * u.cwiseAbs().maxCoeff());
}

TEST(interaction_simulation, CoupledForceEqualsMonolithicKkt) {
  SceneSpec spec;
  auto s = run(spec, {push_right(0.004)});
  const auto& c = s.contacts[0];
  ASSERT_TRUE(c.in_contact);
  Eigen::VectorXd ua, ub;
  s.sim->displacements(0, ua);
  s.sim->displacements(1, ub);
  const auto scene = testing::make_scene(spec);
  const auto& ma = s.sim->mesh(0);
  const auto& mb = s.sim->mesh(1);
  const auto& fixed = s.sim->fixed_nodes(0);  // the scene's plus the carved-out interior nodes
  const auto ka = fem::assemble_stiffness(ma, fem::MaterialMap::uniform(scene.meshes[0].material));
  const auto kb = fem::assemble_stiffness(mb, fem::MaterialMap::uniform(scene.meshes[1].material));
  const auto surface = fusion::TriangleSurface::of(mb);
  // The coupling map comes from the host before carving (same vertex ids).
  const auto& whole = scene.meshes[0];
  ASSERT_EQ(whole.mesh.num_vertices(), ma.num_vertices());
  const auto boundary = fusion::find_new_boundary(whole.mesh, surface);
  const auto map = fusion::build_coupling_map(whole.mesh.vertices(), boundary, surface);
  // Unknowns [u_A, u_B, multipliers]; rows: fixed dofs, prescribed contact dofs, tie rows.
  const int na = static_cast<int>(3 * ma.num_vertices()),
            nb = static_cast<int>(3 * mb.num_vertices());
  std::vector<Eigen::Triplet<double>> t;
  for (int j = 0; j < ka.outerSize(); ++j)
    for (fem::SparseMatrix::InnerIterator it(ka, j); it; ++it)
      t.emplace_back(it.row(), j, it.value());
  for (int j = 0; j < kb.outerSize(); ++j)
    for (fem::SparseMatrix::InnerIterator it(kb, j); it; ++it)
      t.emplace_back(na + it.row(), na + j, it.value());
  int row = na + nb;
  std::vector<double> rhs;
  auto constraint = [&](const std::vector<std::pair<int, double>>& coeffs, double value) {
    for (const auto& [col, w] : coeffs) {
      t.emplace_back(row, col, w);
      t.emplace_back(col, row, w);
    }
    rhs.push_back(value);
    ++row;
  };
  for (int v : fixed)
    for (int a = 0; a < 3; ++a) constraint({{3 * v + a, 1.0}}, 0.0);
  const int first_prescribed = row;
  for (int v : c.nodes)
    for (int a = 0; a < 3; ++a) constraint({{3 * v + a, 1.0}}, ua[3 * v + a]);
  const int end_prescribed = row;
  for (std::size_t k = 0; k < map.embedded_nodes.size(); ++k) {
    const auto& sp = map.embedded_on_boundary[k];
    const auto& tri = boundary.triangles[sp.triangle];
    for (int a = 0; a < 3; ++a)
      constraint({{3 * tri[0] + a, sp.weights[0]},
                  {3 * tri[1] + a, sp.weights[1]},
                  {3 * tri[2] + a, sp.weights[2]},
                  {na + 3 * map.embedded_nodes[k] + a, -1.0}},
                 0.0);
  }
  Eigen::SparseMatrix<double> kkt(row, row);
  kkt.setFromTriplets(t.begin(), t.end());
  Eigen::VectorXd b = Eigen::VectorXd::Zero(row);
  for (std::size_t i = 0; i < rhs.size(); ++i) b[na + nb + static_cast<int>(i)] = rhs[i];
  Eigen::SparseLU<Eigen::SparseMatrix<double>> lu(kkt);
  ASSERT_EQ(lu.info(), Eigen::Success);
  const Eigen::VectorXd x = lu.solve(b);
  Vec3 force = Vec3::Zero();  // K u + C^T mu = 0: the tool force is the sum of the multipliers
  for (int r = first_prescribed; r < end_prescribed; ++r) force[(r - first_prescribed) % 3] += x[r];
  EXPECT_LE((force - c.force_n).norm(), 1e-9 * c.force_n.norm());
  const double scale = ua.cwiseAbs().maxCoeff();
  EXPECT_LE((x.head(na) - ua).cwiseAbs().maxCoeff(), 1e-9 * scale);
  EXPECT_LE((x.segment(na, nb) - ub).cwiseAbs().maxCoeff(), 1e-9 * scale);
}

TEST(interaction_simulation, CachedFullFieldEqualsSparseSolve) {
  SimulationOptions cached;
  cached.cache_full_field_columns = true;
  auto a = run(SceneSpec{}, {push_right(0.004)});
  auto b = run(SceneSpec{}, {push_right(0.004)}, cached);
  ASSERT_TRUE(a.contacts[0].in_contact);
  EXPECT_EQ(a.contacts[0].force_n, b.contacts[0].force_n);
  for (int m = 0; m < 2; ++m) {
    Eigen::VectorXd ua, ub;
    a.sim->displacements(m, ua);
    b.sim->displacements(m, ub);
    EXPECT_LE((ua - ub).cwiseAbs().maxCoeff(), 1e-9 * ua.cwiseAbs().maxCoeff()) << "mesh " << m;
  }
  EXPECT_LE(b.sim->tie_residual_m(), 1e-9 * 0.004);
}

TEST(interaction_simulation, ComplianceCacheRoundTrip) {
  const auto dir = neurosim::testing::temp_dir("interaction_cache");
  SimulationOptions options;
  options.compliance_cache_dir = dir.string();
  auto a = run(SceneSpec{}, {push_right(0.004)}, options);
  EXPECT_EQ(a.sim->setup_stats().cache_hits, 0);
  EXPECT_EQ(a.sim->setup_stats().factor_cache_hits, 0);
  auto b = run(SceneSpec{}, {push_right(0.004)}, options);
  // The boundary operator and the host's factor both read: the same numbers bit for bit.
  EXPECT_EQ(b.sim->setup_stats().cache_hits, 1);
  EXPECT_EQ(b.sim->setup_stats().factor_cache_hits, 1);
  EXPECT_EQ(a.contacts[0].force_n, b.contacts[0].force_n);
  EXPECT_EQ(a.contacts[0].stiffness_n_per_m, b.contacts[0].stiffness_n_per_m);
  for (int m = 0; m < a.sim->num_meshes(); ++m) {
    Eigen::VectorXd ua, ub;
    a.sim->displacements(m, ua);
    b.sim->displacements(m, ub);
    ASSERT_EQ(ua.size(), ub.size());
    EXPECT_EQ(ua, ub) << "mesh " << m;
  }
  // Another embedded material is another boundary operator on the same host factor.
  SceneSpec other;
  other.embedded_e_pa = 2.0e5;
  auto c = run(other, {push_right(0.004)}, options);
  EXPECT_EQ(c.sim->setup_stats().cache_hits, 0);
  EXPECT_EQ(c.sim->setup_stats().factor_cache_hits, 1);
  // Another host material: neither (another mesh: fem_factor_cache_test).
  SceneSpec host_e;
  host_e.host_e_pa = 1.2e6;
  auto e = run(host_e, {push_right(0.004)}, options);
  EXPECT_EQ(e.sim->setup_stats().cache_hits, 0);
  EXPECT_EQ(e.sim->setup_stats().factor_cache_hits, 0);
  // A damaged file is ignored (recomputed), never trusted.
  for (const auto& entry : std::filesystem::directory_iterator(dir))
    std::filesystem::resize_file(entry.path(), 40);
  auto d = run(SceneSpec{}, {push_right(0.004)}, options);
  EXPECT_EQ(d.sim->setup_stats().cache_hits, 0);
  EXPECT_EQ(d.sim->setup_stats().factor_cache_hits, 0);
  EXPECT_EQ(a.contacts[0].force_n, d.contacts[0].force_n);
  std::filesystem::remove_all(dir);
}

TEST(interaction_simulation, PrecomputedColumnsGiveTheSameStep) {
  SimulationOptions pre;
  pre.precompute_contact_columns = true;
  auto a = run(SceneSpec{}, {push_right(0.004)});
  auto b = run(SceneSpec{}, {push_right(0.004)}, pre);
  EXPECT_GT(a.stats.columns_computed, 0);
  EXPECT_EQ(b.stats.columns_computed, 0);
  EXPECT_GT(b.sim->setup_stats().columns_s, 0.0);
  EXPECT_EQ(a.contacts[0].nodes, b.contacts[0].nodes);
  EXPECT_LE((a.contacts[0].force_n - b.contacts[0].force_n).norm(),
            1e-12 * a.contacts[0].force_n.norm());
}

TEST(interaction_simulation, EmbeddedMeshWithFixedNodes) {
  SceneSpec spec;
  spec.embedded_fixed = true;  // the cylinder's end face at y = 0.02 is held
  auto on = run(spec, {push_right(0.004)});
  EXPECT_TRUE(on.stats.converged);
  EXPECT_TRUE(on.contacts[0].in_contact);
  EXPECT_LE(on.sim->tie_residual_m(), 1e-9 * 0.004);
  Eigen::VectorXd u;
  on.sim->displacements(1, u);
  for (int v : on.sim->fixed_nodes(1)) EXPECT_EQ(u.segment<3>(3 * v).norm(), 0.0) << v;
  spec.coupling = false;
  auto off = run(spec, {push_right(0.004)});
  EXPECT_TRUE(off.sim->mesh_active(1));  // a body of its own now, untouched inside the cube
  off.sim->displacements(1, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);
}

TEST(interaction_simulation, IterativeBaselineMatchesExact) {
  SceneSpec spec;
  auto exact = run(spec, {push_right(0.004)});
  spec.iterative = true;
  auto iter = run(spec, {push_right(0.004)});
  ASSERT_TRUE(iter.contacts[0].in_contact);
  EXPECT_EQ(exact.contacts[0].nodes, iter.contacts[0].nodes);
  const double f = exact.contacts[0].force_n.norm();
  EXPECT_LE((exact.contacts[0].force_n - iter.contacts[0].force_n).norm(), 1e-9 * f);
  // The iteration did run (and converged) instead of the factored operator.
  const auto report = iter.sim->iterative_report(0);
  EXPECT_GT(report.solves, 0);
  EXPECT_GT(report.max_iterations, 1);
  EXPECT_EQ(report.unconverged, 0);
  EXPECT_EQ(exact.sim->iterative_report(0).solves, 0);
  Eigen::VectorXd ue, ui;
  exact.sim->displacements(1, ue);
  iter.sim->displacements(1, ui);
  EXPECT_LE((ue - ui).cwiseAbs().maxCoeff(), 1e-9 * ue.cwiseAbs().maxCoeff());
}

// The rows are found on the surface deformed by the last answer: the pose is held until that
// geometry settles (a fixed point, reached to round-off in a few steps), then moved by h. K is the
// flat-contact linearization -N (W_AA^-1) N^T: each row a plane with a fixed normal. The node and
// edge rows' normals are radial from the tip centre, so they also turn with the tip (by h / rho,
// rho ~ the tip radius): across the push that adds up to sum(lambda) h / rho, and along it the
// turn of the planes through the rows' displacement u (u_t / rho relative), and the rows' points
// and weights move as the surface is found again from rest in each step: 10 % here, a 15 mm tip
// 3 mm into 12 mm elements. K takes the node and edge rows' turn (contact_step.cpp normal_turn),
// not the projected face rows' nor the points sliding over their triangles.
//
// The check: the tool held 3 mm into the cube's face until the geometry settles, then moved by h = 0.1 um
// further in: the finite difference of the force against K, within 15 % along the push and, across
// it, the rows' turn (1.5 sum(lambda) / (0.9 r)); K pushes back (negative along the push), and its
// symmetric part is negative semidefinite but for the turn, which is destabilising across a node
// (a sphere on a point is pushed off it sideways): its positive eigenvalues at most
// 1.5 |F| / (0.9 r) as above (measured 279 / 279 / 287 N/m against 3252 / 3252 / 3677).
// Before the turn was in K the largest eigenvalue was 0 to 1e-9 of the smallest.
void expect_stiffness_matches_finite_difference(const SceneSpec& spec,
                                                const SimulationOptions& options,
                                                const ToolPose& p = push_right(0.003)) {
  auto sim = Simulation::build(testing::make_scene(spec), options);
  std::vector<ToolContact> c0, c1;
  StepStats st;
  for (int k = 0; k < 30; ++k) sim->step({p}, c0, st);
  ASSERT_TRUE(c0[0].in_contact);
  ToolPose q = p;
  const double h = 1e-7;
  q.tip_m.x() -= h;
  sim->step({q}, c1, st);
  ASSERT_EQ(c0[0].nodes, c1[0].nodes);
  const Vec3 fd = (c1[0].force_n - c0[0].force_n) / h;
  const Vec3 model = c0[0].stiffness_n_per_m * Vec3(-1.0, 0.0, 0.0);
  std::printf("dF/dx (%.1f %.1f %.1f), K e_x (%.1f %.1f %.1f) N/m\n", fd.x(), fd.y(), fd.z(),
              model.x(), model.y(), model.z());
  EXPECT_LE(std::abs(fd.x() - model.x()), 0.15 * model.norm());
  EXPECT_LE((fd - model).norm(), 0.15 * model.norm() + 1.5 * c0[0].force_n.norm() /
                                                           (0.9 * spec.tip_radius_m));
  // Pushing deeper raises the force: dF/dx is negative along the push.
  EXPECT_LT(c0[0].stiffness_n_per_m(0, 0), 0.0);
  const Eigen::SelfAdjointEigenSolver<Mat3> eig(
      0.5 * (c0[0].stiffness_n_per_m + c0[0].stiffness_n_per_m.transpose()));
  const double turn = 1.5 * c0[0].force_n.norm() / (0.9 * spec.tip_radius_m);
  std::printf("sym(K) eigenvalues %.1f %.1f %.1f N/m, 1.5 |F| / (0.9 r) %.1f N/m\n",
              eig.eigenvalues()[0], eig.eigenvalues()[1], eig.eigenvalues()[2], turn);
  EXPECT_LE(eig.eigenvalues().maxCoeff(), turn);
}

TEST(interaction_simulation, StiffnessMatchesFiniteDifference) {
  expect_stiffness_matches_finite_difference(SceneSpec{}, SimulationOptions{});
}

// The same with each row's load spread over a local edge, smooth tip rows and the near field in
// series (SimulationOptions contact_spread 1, contact_smooth_normals, contact_near_field): the
// near field's compliance falls as the tip goes deeper (Hertz's secant), so K adds its change
// (contact_step.cpp near_field_tangent). Without it the finite difference was 1.47x K (its x
// component 4809 N/m off a K of 10120 N/m); the turn of the rows is as above.
TEST(interaction_simulation, StiffnessMatchesFiniteDifferenceWithTheNearField) {
  SimulationOptions options;
  options.contact_spread = 1.0;
  options.contact_smooth_normals = true;
  options.contact_near_field = true;
  expect_stiffness_matches_finite_difference(SceneSpec{}, options);
}

// The shaft's near field (contact_shaft_near_field, contact_step.cpp near_field_of_shaft) in
// series with the shaft's rows, its change with the shaft's depth in K: a 2 mm tip 1.5 mm into
// the face, its axis 10 degrees off the face, so that the 2 mm shaft leaving it stays in the
// tissue for about 8 mm (12 mm cells: the spread is the edge's, both near fields act). Measured
// dF/dx 5244 N/m against K 5483 (4.5 %); each part's term with the whole tool's K in place of
// its own (K_b, near_field_tangent) gave K 7412 (41 % off; the tip's near field alone 20650
// against 17743 with K_b, 28807 without; no near field 21258 both).
TEST(interaction_simulation, StiffnessMatchesFiniteDifferenceWithTheShaftNearField) {
  SceneSpec spec;
  spec.tip_radius_m = 0.002;
  ToolPose p = push_right(0.0015, spec.tip_radius_m);
  const double tilt = 10.0 * M_PI / 180.0;
  p.axis = Vec3(std::sin(tilt), 0.0, std::cos(tilt));
  SimulationOptions options;
  expect_stiffness_matches_finite_difference(spec, options, p);
}

TEST(interaction_simulation, UnilateralNoPull) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({push_right(-0.001)}, c, st);  // 1 mm clear of the surface
  EXPECT_FALSE(c[0].in_contact);
  EXPECT_EQ(c[0].force_n.norm(), 0.0);
  sim->step({push_right(0.002)}, c, st);
  EXPECT_TRUE(c[0].in_contact);
  EXPECT_GT(c[0].force_n.x(), 0.0);
  sim->step({push_right(-0.0005)}, c, st);  // withdrawn: nothing holds the tool
  EXPECT_FALSE(c[0].in_contact);
  Eigen::VectorXd u;
  sim->displacements(0, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);
}

TEST(interaction_simulation, RejectsNonFinitePose) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> c;
  StepStats st;
  ToolPose p = push_right(0.002);
  p.tip_m.y() = std::nan("");
  EXPECT_THROW(sim->step({p}, c, st), std::invalid_argument);
  ToolPose q = push_right(0.002);
  q.axis = Vec3(std::numeric_limits<double>::infinity(), 0, 0);
  EXPECT_THROW(sim->step({q}, c, st), std::invalid_argument);
  ToolPose r = push_right(0.002);
  r.tool = 5;
  EXPECT_THROW(sim->step({r}, c, st), std::invalid_argument);
}

TEST(interaction_simulation, DeterministicSteps) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> a, b;
  StepStats st;
  sim->step({push_right(0.003)}, a, st);
  sim->step({push_right(0.001)}, b, st);
  sim->step({push_right(0.003)}, b, st);
  // LINEAR: the rows are found again from rest in every step, so the answer is the pose's alone
  // (the LCP's warm start from the last step changes its path, not its solution).
  EXPECT_LE((a[0].force_n - b[0].force_n).norm(), 1e-12 * a[0].force_n.norm());
  EXPECT_LE((a[0].stiffness_n_per_m - b[0].stiffness_n_per_m).norm(),
            1e-12 * a[0].stiffness_n_per_m.norm());
  EXPECT_EQ(a[0].nodes, b[0].nodes);
}

// --- stability: finite, bounded, the LCP converges or says it did not ---

constexpr double kBoundN = 1e4;  // E_max x (0.1 m)^2: the whole cross-section at 100 % strain

TEST(interaction_stability, StiffnessRatio1e4) {
  for (double e_emb : {1.0e2, 1.0e10}) {
    SceneSpec spec;
    spec.embedded_e_pa = e_emb;
    auto s = run(spec, {push_right(0.005)});
    EXPECT_TRUE(s.stats.converged) << e_emb;
    expect_sane(s, e_emb > 1e6 ? 1e4 * kBoundN : kBoundN);
    EXPECT_LE(s.sim->tie_residual_m(), 1e-9 * 0.005) << e_emb;
  }
}

TEST(interaction_stability, NearlyIncompressible) {
  SceneSpec spec;
  spec.nu = 0.499;
  auto s = run(spec, {push_right(0.005)});
  EXPECT_TRUE(s.stats.converged);
  expect_sane(s, kBoundN);
  EXPECT_LE(s.sim->tie_residual_m(), 1e-9 * 0.005);
}

TEST(interaction_stability, DeepPush30Percent) {
  auto s = run(SceneSpec{}, {push_right(0.03)});
  EXPECT_TRUE(s.stats.converged);
  EXPECT_TRUE(s.contacts[0].in_contact);
  expect_sane(s, kBoundN);
}

TEST(interaction_stability, ToolJumps10cm) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({push_right(-0.002)}, c, st);
  for (double depth : {0.1, 0.002, 0.102, -0.002}) {
    sim->step({push_right(depth)}, c, st);
    EXPECT_TRUE(c[0].force_n.allFinite());
    EXPECT_LE(c[0].force_n.norm(), kBoundN) << depth;
    EXPECT_TRUE(st.converged || !c[0].converged);
  }
  EXPECT_FALSE(c[0].in_contact);
}

TEST(interaction_stability, ContactOnSliver) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  const auto& m = sim->mesh(0);
  // The worst-shaped tetrahedron with a face on the free surface; push at that face's centre.
  int worst = -1;
  double worst_q = 2.0;
  for (std::size_t f = 0; f < m.surface().size(); ++f) {
    const int t = m.surface_tet()[f];
    const auto& tet = m.tets()[t];
    const double q = 6.0 * std::sqrt(2.0) * m.tet_volume(t) /
                     std::pow(((m.vertices()[tet[0]] - m.vertices()[tet[1]]).norm() +
                               (m.vertices()[tet[2]] - m.vertices()[tet[3]]).norm()) /
                                  2.0,
                              3);
    const Vec3 c = (m.vertices()[m.surface()[f][0]] + m.vertices()[m.surface()[f][1]] +
                    m.vertices()[m.surface()[f][2]]) /
                   3.0;
    if (c.z() < 0.01) continue;  // the fixed bottom
    // The free surface only (not the carved faces around the cylinder, S').
    bool free = true;
    for (int v : m.surface()[f]) free = free && sim->body_of(0)->contact_slot(v) >= 0;
    if (!free) continue;
    if (q < worst_q) {
      worst_q = q;
      worst = static_cast<int>(f);
    }
  }
  ASSERT_GE(worst, 0);
  const auto& tri = m.surface()[worst];
  const Vec3 a = m.vertices()[tri[0]], b = m.vertices()[tri[1]], cc = m.vertices()[tri[2]];
  const Vec3 n = (b - a).cross(cc - a).normalized();
  ToolPose p;
  p.tip_m = (a + b + cc) / 3.0 + (SceneSpec{}.tip_radius_m - 0.004) * n;
  p.axis = n;
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({p}, c, st);
  EXPECT_TRUE(st.converged);
  EXPECT_TRUE(c[0].in_contact);
  EXPECT_TRUE(c[0].force_n.allFinite());
  EXPECT_LE(c[0].force_n.norm(), kBoundN);
}

TEST(interaction_stability, TwoToolsOnTheSameNode) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> one, two;
  StepStats st;
  // Each held until the deformed surface the rows are found on settles (a fixed point).
  for (int k = 0; k < 30; ++k) sim->step({push_right(0.003)}, one, st);
  for (int k = 0; k < 30; ++k) sim->step({push_right(0.003), push_right(0.003)}, two, st);
  EXPECT_TRUE(st.converged);
  ASSERT_EQ(two.size(), 2u);
  // The nodes are pushed once (one row per feature; the deeper tool carries it): the tools share
  // what one tool would feel.
  EXPECT_LE((two[0].force_n + two[1].force_n - one[0].force_n).norm(),
            1e-7 * one[0].force_n.norm());
  // A deeper second tool takes the node over and feels more than the first alone.
  sim->step({push_right(0.003), push_right(0.004)}, two, st);
  EXPECT_TRUE(st.converged);
  EXPECT_GT(two[1].force_n.norm(), one[0].force_n.norm());
  EXPECT_TRUE(two[0].force_n.allFinite());
}

TEST(interaction_stability, ToolInsideTheEmbeddedMesh) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  std::vector<ToolContact> c;
  StepStats st;
  ToolPose p;
  p.tip_m = Vec3(0.05, 0.05, 0.05);  // the cylinder's axis
  p.axis = Vec3::UnitX();
  sim->step({p}, c, st);
  EXPECT_TRUE(st.converged || !c[0].converged);
  EXPECT_TRUE(c[0].force_n.allFinite());
  EXPECT_LE(c[0].force_n.norm(), kBoundN);
  EXPECT_LE(sim->tie_residual_m(), 1e-9 * 0.05);
}

}  // namespace
// The Model/State split: one constant Model serves independent States; a State's answer depends
// only on the Model and the poses it is stepped with (not on another State's steps), and equals
// the Simulation's. The rows follow the surface deformed by the last answer, so a held pose
// settles to one answer whatever came before (a fixed point: b's other presses are forgotten).
TEST(interaction_simulation, OneModelServesIndependentStates) {
  const SceneSpec spec;
  const auto model = build_model(testing::make_scene(spec));
  auto a = make_state(*model);
  auto b = make_state(*model);
  std::vector<ToolContact> ca, cb, cs;
  StepStats st;
  const int hold = 30;
  for (int k = 0; k < hold; ++k) step(*model, *a, {push_right(0.004)}, ca, st);
  ASSERT_TRUE(ca[0].in_contact);
  step(*model, *b, {push_right(0.002)}, cb, st);
  step(*model, *b, {push_right(0.006)}, cb, st);
  for (int k = 0; k < hold; ++k) step(*model, *b, {push_right(0.004)}, cb, st);
  const double f = ca[0].force_n.norm();
  EXPECT_LE((cb[0].force_n - ca[0].force_n).norm(), 1e-9 * f);
  EXPECT_LE((cb[0].stiffness_n_per_m - ca[0].stiffness_n_per_m).norm(),
            1e-9 * ca[0].stiffness_n_per_m.norm());
  // State a is untouched by b's steps: the same pose again gives the same answer.
  const Vec3 before = ca[0].force_n;
  step(*model, *a, {push_right(0.004)}, ca, st);
  EXPECT_LE((ca[0].force_n - before).norm(), 1e-12 * f);
  auto sim = Simulation::build(testing::make_scene(spec));
  for (int k = 0; k < hold; ++k) sim->step({push_right(0.004)}, cs, st);
  EXPECT_LE((cs[0].force_n - before).norm(), 1e-12 * f);
}

}  // namespace neurosim::interaction
