// SLIDING coupling (frictionless unilateral contact between the host's new boundary S' and the
// embedded mesh's surface), on the small cube/cylinder scene: no interpenetration, compressive
// forces only, complementarity checked from the full fields, separation where TIE would drag,
// the variational ordering against TIE, stability, mixed TIE + SLIDING scenes.
#include "interaction_fixtures.hpp"
#include "server/interaction/simulation.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {
namespace {

using testing::SceneSpec;

constexpr int kCube = 0, kCylinder = 1, kRod = 2;

using testing::push_right;
using testing::run;
using testing::Stepped;

SceneSpec sliding_spec() {
  SceneSpec s;
  s.sliding = true;
  return s;
}

// Gaps g = n . (sum w u_A - u_B) + g0 of every pair, from the full fields (independent of the
// LCP's own bookkeeping), and the pairs with their forces.
struct Gaps {
  std::vector<SlidingPairState> pairs;
  std::vector<double> g_m;
  double min_m{std::numeric_limits<double>::infinity()};
  double max_m{-std::numeric_limits<double>::infinity()};
};

Gaps gaps(const Simulation& sim, int embedded = kCylinder) {
  Gaps out;
  sim.sliding_pairs(embedded, out.pairs);
  Eigen::VectorXd ua, ub;
  sim.displacements(kCube, ua);
  sim.displacements(embedded, ub);
  for (const auto& p : out.pairs) {
    Vec3 u = Vec3::Zero();
    for (int a = 0; a < 3; ++a) u += p.weights[a] * ua.segment<3>(3 * p.host_nodes[a]);
    const double g = p.normal.dot(u - ub.segment<3>(3 * p.embedded_node)) + p.initial_gap_m;
    out.g_m.push_back(g);
    out.min_m = std::min(out.min_m, g);
    out.max_m = std::max(out.max_m, g);
  }
  return out;
}

TEST(interaction_sliding, SceneLoadsAndRunsThroughSimulation) {
  const double depth = 0.004;
  auto s = run(sliding_spec(), {push_right(depth)});
  ASSERT_TRUE(s.stats.converged);
  ASSERT_TRUE(s.contacts[0].in_contact);
  EXPECT_GT(s.contacts[0].force_n.x(), 0.0);
  EXPECT_TRUE(s.sim->mesh_active(kCylinder));
  EXPECT_GT(s.sim->setup_stats().sliding_rows, 0);
  EXPECT_EQ(s.sim->setup_stats().tied_nodes, 0);
  EXPECT_EQ(s.stats.sliding_rows, s.sim->setup_stats().sliding_rows);
  EXPECT_GT(s.stats.sliding_active, 0);
  std::vector<SlidingPairState> pairs;
  s.sim->sliding_pairs(kCylinder, pairs);
  EXPECT_EQ(static_cast<int>(pairs.size()), s.sim->setup_stats().sliding_rows);
  s.sim->sliding_pairs(kCube, pairs);
  EXPECT_TRUE(pairs.empty());
  // Nothing to tie: the tie residual is zero; the fields are finite.
  EXPECT_EQ(s.sim->tie_residual_m(), 0.0);
  for (int m = 0; m < s.sim->num_meshes(); ++m) {
    Eigen::VectorXd u;
    s.sim->displacements(m, u);
    EXPECT_TRUE(u.allFinite()) << m;
  }
}

TEST(interaction_sliding, RejectsIterativeMethod) {
  SceneSpec spec = sliding_spec();
  spec.iterative = true;
  try {
    Simulation::build(testing::make_scene(spec));
    FAIL() << "ITERATIVE with SLIDING was accepted";
  } catch (const std::runtime_error& ex) {
    EXPECT_NE(std::string(ex.what()).find("cube / cylinder"), std::string::npos) << ex.what();
    EXPECT_NE(std::string(ex.what()).find("SLIDING"), std::string::npos) << ex.what();
  }
}

// (a) The host pushed towards the embedded mesh: no interpenetration, compressive forces only,
// complementarity, and the embedded mesh is pushed the way the host moves.
TEST(interaction_sliding, PushNoInterpenetrationCompressiveOnly) {
  const double depth = 0.005;
  auto s = run(sliding_spec(), {push_right(depth)});
  ASSERT_TRUE(s.stats.converged);
  ASSERT_TRUE(s.contacts[0].in_contact);
  const Gaps g = gaps(*s.sim);
  ASSERT_FALSE(g.pairs.empty());
  EXPECT_GE(g.min_m, -1e-9 * depth);
  EXPECT_LE(s.sim->sliding_penetration_m(), 1e-9 * depth);
  int active = 0;
  double largest = 0.0;
  for (const auto& p : g.pairs) largest = std::max(largest, p.force_n);
  for (std::size_t k = 0; k < g.pairs.size(); ++k) {
    const auto& p = g.pairs[k];
    EXPECT_GE(p.force_n, 0.0) << k;
    EXPECT_TRUE(std::isfinite(p.force_n));
    // lambda g = 0: a pair that carries force is closed (to round-off).
    if (p.force_n > 1e-9 * largest) {
      ++active;
      EXPECT_LE(std::abs(g.g_m[k]), 1e-9 * depth) << k;
    }
  }
  EXPECT_GT(active, 0);
  EXPECT_GT(largest, 0.0);
  // The cylinder is pushed towards -x with the host.
  Eigen::VectorXd ub;
  s.sim->displacements(kCylinder, ub);
  double mean_x = 0.0;
  for (int v = 0; v < ub.size() / 3; ++v) mean_x += ub[3 * v];
  EXPECT_LT(mean_x, 0.0);
  EXPECT_GT(ub.cwiseAbs().maxCoeff(), 0.01 * depth);
  // Forces balance: the sliding forces push A along +n and B along -n; with B floating, the
  // anchor of its rigid modes carries only a tiny share of their resultant.
  Vec3 resultant = Vec3::Zero();
  double total = 0.0;
  for (const auto& p : g.pairs) {
    resultant += p.force_n * p.normal;
    total += p.force_n;
  }
  EXPECT_LE(resultant.norm(), 1e-3 * total);
}

// (b) Where the host moves away from the embedded mesh, the meshes separate without force
// (the embedded mesh does not follow), whereas TIE drags those nodes along.
TEST(interaction_sliding, PulledSideSeparatesWithoutForce) {
  const double depth = 0.005;
  auto slide = run(sliding_spec(), {push_right(depth)});
  auto tie = run(SceneSpec{}, {push_right(depth)});
  ASSERT_TRUE(slide.stats.converged && tie.stats.converged);
  const Gaps g = gaps(*slide.sim);
  int open = 0;
  for (std::size_t k = 0; k < g.pairs.size(); ++k) {
    if (g.g_m[k] > 1e-6 * depth) {
      ++open;
      EXPECT_EQ(g.pairs[k].force_n, 0.0) << k;  // separated pairs carry nothing
    }
  }
  EXPECT_GT(open, 0);
  EXPECT_LT(open, static_cast<int>(g.pairs.size()));
  // TIE keeps every node on the host (its residual is round-off), so where SLIDING opens a gap
  // the tie pulls the cylinder along.
  EXPECT_LE(tie.sim->tie_residual_m(), 1e-9 * depth);
  EXPECT_GT(g.max_m, 1e-3 * depth);
}

// (b) With the fusion's clearance as initial gap, a push too small to close it leaves the
// cylinder unloaded and still (no other load, so exactly zero), while TIE drags it.
TEST(interaction_sliding, ClearanceLeavesEmbeddedMeshStill) {
  SimulationOptions geometric;
  geometric.sliding_geometric_gap = true;
  auto probe = Simulation::build(testing::make_scene(sliding_spec()), geometric);
  std::vector<SlidingPairState> pairs;
  probe->sliding_pairs(kCylinder, pairs);
  double smallest = std::numeric_limits<double>::infinity(), largest = 0.0;
  for (const auto& p : pairs) {
    EXPECT_GE(p.initial_gap_m, 0.0);
    smallest = std::min(smallest, p.initial_gap_m);
    largest = std::max(largest, p.initial_gap_m);
  }
  ASSERT_GT(largest, 0.0);
  // A push small against the clearance.
  const double depth = 1e-4;
  std::vector<ToolContact> c;
  StepStats st;
  probe->step({push_right(depth)}, c, st);
  ASSERT_TRUE(st.converged);
  ASSERT_TRUE(c[0].in_contact);
  probe->sliding_pairs(kCylinder, pairs);
  const Gaps g = gaps(*probe);
  if (smallest > 1e-3) {
    for (const auto& p : pairs) EXPECT_EQ(p.force_n, 0.0);
    Eigen::VectorXd ub;
    probe->displacements(kCylinder, ub);
    EXPECT_EQ(ub.cwiseAbs().maxCoeff(), 0.0);
  }
  EXPECT_GE(g.min_m, -1e-9 * depth);
  auto tie = run(SceneSpec{}, {push_right(depth)});
  Eigen::VectorXd ut;
  tie.sim->displacements(kCylinder, ut);
  EXPECT_GT(ut.cwiseAbs().maxCoeff(), 0.01 * depth);
  // Pushed far enough, the clearance closes and the unilateral rows hold.
  const double deep = 0.03;
  probe->step({push_right(deep)}, c, st);
  ASSERT_TRUE(st.converged);
  EXPECT_GE(gaps(*probe).min_m, -1e-9 * deep);
  EXPECT_LE(probe->sliding_penetration_m(), 1e-9 * deep);
}

// (c) Variational ordering on the same push: frictionless unilateral pairs constrain less than
// the tie (no tangential rows, may separate), so the body is softer with SLIDING and the tool
// feels less; and on every pair SLIDING holds closed, the normal gap closure is zero as with
// TIE (whose normal closure is zero on every pair).
TEST(interaction_sliding, SofterThanTieWhereTangentialRowsAreMissing) {
  const double depth = 0.004;
  auto slide = run(sliding_spec(), {push_right(depth)});
  auto tie = run(SceneSpec{}, {push_right(depth)});
  ASSERT_TRUE(slide.stats.converged && tie.stats.converged);
  auto sorted = [](std::vector<int> v) {
    std::sort(v.begin(), v.end());
    return v;
  };
  ASSERT_EQ(sorted(slide.contacts[0].nodes), sorted(tie.contacts[0].nodes));
  const double fs = slide.contacts[0].force_n.norm(), ft = tie.contacts[0].force_n.norm();
  EXPECT_LE(fs, ft * (1.0 + 1e-12));
  // ... but the cylinder still carries load: softer than the carved host with an (almost)
  // empty cavity, i.e. a cylinder 1e-6 as stiff.
  SceneSpec empty = sliding_spec();
  empty.embedded_e_pa = 1e-1;
  auto hollow = run(empty, {push_right(depth)});
  ASSERT_TRUE(hollow.stats.converged);
  ASSERT_EQ(sorted(hollow.contacts[0].nodes), sorted(slide.contacts[0].nodes));
  const double fh = hollow.contacts[0].force_n.norm();
  EXPECT_GT(fs, fh * (1.0 + 1e-6));
  // The tool sees the softer coupling in its stiffness too (same contact nodes).
  EXPECT_LE(-slide.contacts[0].stiffness_n_per_m(0, 0),
            -tie.contacts[0].stiffness_n_per_m(0, 0) * (1.0 + 1e-12));
  // Normal gap closure on the closed pairs is zero for both kinds.
  const Gaps g = gaps(*slide.sim);
  Eigen::VectorXd ua, ub;
  tie.sim->displacements(kCube, ua);
  tie.sim->displacements(kCylinder, ub);
  int closed = 0;
  for (std::size_t k = 0; k < g.pairs.size(); ++k) {
    const auto& p = g.pairs[k];
    if (!(p.force_n > 0.0)) continue;
    ++closed;
    Vec3 u = Vec3::Zero();
    for (int a = 0; a < 3; ++a) u += p.weights[a] * ua.segment<3>(3 * p.host_nodes[a]);
    const double tie_closure = p.normal.dot(u - ub.segment<3>(3 * p.embedded_node));
    EXPECT_LE(std::abs(tie_closure), 1e-9 * depth) << k;
    EXPECT_LE(std::abs(g.g_m[k]), 1e-9 * depth) << k;
  }
  EXPECT_GT(closed, 0);
}

// The contact stiffness handed to the haptic client includes the sliding rows (finite
// difference of the force along the push, same active sets).
TEST(interaction_sliding, StiffnessMatchesFiniteDifference) {
  auto sim = Simulation::build(testing::make_scene(sliding_spec()));
  std::vector<ToolContact> c0, c1;
  StepStats s0, s1;
  const ToolPose p = push_right(0.003);
  // Held until the deformed surface the rows are found on settles (simulation_test.cpp,
  // StiffnessMatchesFiniteDifference: what K leaves out of the turn of the radial normals).
  for (int k = 0; k < 30; ++k) sim->step({p}, c0, s0);
  ASSERT_TRUE(c0[0].in_contact);
  ToolPose q = p;
  const double h = 1e-8;
  q.tip_m.x() -= h;
  sim->step({q}, c1, s1);
  ASSERT_EQ(c0[0].nodes, c1[0].nodes);
  ASSERT_EQ(s0.sliding_active, s1.sliding_active);
  const Vec3 fd = (c1[0].force_n - c0[0].force_n) / h;
  const Vec3 model = c0[0].stiffness_n_per_m * Vec3(-1.0, 0.0, 0.0);
  EXPECT_LE(std::abs(fd.x() - model.x()), 0.15 * model.norm());
  EXPECT_LE((fd - model).norm(),
            0.15 * model.norm() + 1.5 * c0[0].force_n.norm() / (0.9 * sliding_spec().tip_radius_m));
  EXPECT_LT(c0[0].stiffness_n_per_m(0, 0), 0.0);
}

// Warm start from the last step and a cold start give the same answer (each pose held until the
// deformed surface the rows are found on settles); withdrawing the tool releases everything.
TEST(interaction_sliding, DeterministicAndReleases) {
  auto a = Simulation::build(testing::make_scene(sliding_spec()));
  auto b = Simulation::build(testing::make_scene(sliding_spec()));
  std::vector<ToolContact> ca, cb;
  StepStats st;
  for (int k = 0; k < 30; ++k) a->step({push_right(0.004)}, ca, st);
  b->step({push_right(0.002)}, cb, st);
  b->step({push_right(0.006)}, cb, st);
  for (int k = 0; k < 30; ++k) b->step({push_right(0.004)}, cb, st);
  ASSERT_TRUE(st.converged);
  EXPECT_LE((ca[0].force_n - cb[0].force_n).norm(), 1e-9 * ca[0].force_n.norm());
  a->step({push_right(-0.001)}, ca, st);
  EXPECT_FALSE(ca[0].in_contact);
  EXPECT_EQ(st.sliding_active, 0);
  Eigen::VectorXd u;
  a->displacements(kCylinder, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);
}

// Out of pivots: the step says so and keeps the last good answer (here: none yet); the factor of
// the sliding rows carries over, so the same pose converges after a few more steps, to the
// same answer as with enough pivots.
TEST(interaction_sliding, NonConvergenceReportedLastGoodKept) {
  const double depth = 0.004;
  SimulationOptions one;
  // One LCP per step (the rows of the rest surface), so the pivots of one step carry to the next.
  one.contact_geometry_iterations = 1;
  auto ref = run(sliding_spec(), {push_right(depth)}, one);
  ASSERT_TRUE(ref.stats.converged);
  ASSERT_GT(ref.contacts[0].iterations, 3);
  SimulationOptions few;
  few.lcp_max_iterations = 3;
  few.lcp_iterations_per_sliding_row = 0;
  few.contact_geometry_iterations = 1;
  auto sim = Simulation::build(testing::make_scene(sliding_spec()), few);
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({push_right(depth)}, c, st);
  EXPECT_FALSE(st.converged);
  EXPECT_FALSE(c[0].converged);
  EXPECT_FALSE(c[0].in_contact);  // the last good answer: no contact yet
  Eigen::VectorXd u;
  sim->displacements(kCylinder, u);
  EXPECT_EQ(u.cwiseAbs().maxCoeff(), 0.0);
  int steps = 1;
  while (!st.converged && steps < 200) {
    sim->step({push_right(depth)}, c, st);
    ++steps;
  }
  ASSERT_TRUE(st.converged) << steps;
  EXPECT_GT(steps, 1);
  EXPECT_LE((c[0].force_n - ref.contacts[0].force_n).norm(), 1e-9 * ref.contacts[0].force_n.norm());
  EXPECT_GE(gaps(*sim).min_m, -1e-9 * depth);
}

TEST(interaction_sliding, EmbeddedMeshWithFixedNodes) {
  SceneSpec spec = sliding_spec();
  spec.embedded_fixed = true;
  const double depth = 0.004;
  auto s = run(spec, {push_right(depth)});
  ASSERT_TRUE(s.stats.converged);
  EXPECT_GE(gaps(*s.sim).min_m, -1e-9 * depth);
  Eigen::VectorXd u;
  s.sim->displacements(kCylinder, u);
  for (int v : s.sim->fixed_nodes(kCylinder)) EXPECT_EQ(u.segment<3>(3 * v).norm(), 0.0) << v;
  EXPECT_GT(u.cwiseAbs().maxCoeff(), 0.0);
}

// Mixed scenes: the cylinder slides and the rod is tied, the other way round, and both slide
// (two sliding couplings on one host: their rows interact through the host); every one holds.
TEST(interaction_sliding, MixedTieAndSliding) {
  struct Case {
    bool cylinder_slides;
    const char* rod_kind;
  };
  for (const Case& k : {Case{true, "TIE"}, Case{false, "SLIDING"}, Case{true, "SLIDING"}}) {
    SceneSpec spec;
    spec.sliding = k.cylinder_slides;
    spec.rod_kind = k.rod_kind;
    const std::string what =
        std::string(k.cylinder_slides ? "SLIDING" : "TIE") + " + " + k.rod_kind;
    const bool rod_slides = spec.rod_kind == "SLIDING";
    const double depth = 0.005;
    // Push the top face down, above the rod.
    ToolPose p;
    p.tip_m = Vec3(0.02, 0.05, 0.1 + spec.tip_radius_m - depth);
    p.axis = Vec3::UnitZ();
    auto s = run(spec, {p});
    ASSERT_TRUE(s.stats.converged) << what;
    ASSERT_TRUE(s.contacts[0].in_contact) << what;
    EXPECT_EQ(s.sim->setup_stats().tied_nodes > 0, !(k.cylinder_slides && rod_slides)) << what;
    EXPECT_GT(s.sim->setup_stats().sliding_rows, 0);
    EXPECT_LE(s.sim->tie_residual_m(), 1e-9 * depth) << what;
    EXPECT_LE(s.sim->sliding_penetration_m(), 1e-9 * depth) << what;
    if (k.cylinder_slides) {
      EXPECT_GE(gaps(*s.sim, kCylinder).min_m, -1e-9 * depth) << what;
    }
    if (rod_slides) {
      EXPECT_GE(gaps(*s.sim, kRod).min_m, -1e-9 * depth) << what;
    }
    for (int m = 0; m < s.sim->num_meshes(); ++m) {
      Eigen::VectorXd u;
      s.sim->displacements(m, u);
      EXPECT_TRUE(u.allFinite());
      EXPECT_GT(u.cwiseAbs().maxCoeff(), 0.0) << what << " mesh " << m;
    }
  }
}

// --- (d) stability: finite, bounded, converged or reported, no interpenetration when converged

constexpr double kBoundN = 1e4;  // E_max x (0.1 m)^2: the whole cross-section at 100 % strain

void expect_sane(Simulation& sim, const std::vector<ToolContact>& contacts, const StepStats& st,
                 double depth, double bound_n) {
  for (const auto& c : contacts) {
    EXPECT_TRUE(c.force_n.allFinite());
    EXPECT_TRUE(c.stiffness_n_per_m.allFinite());
    EXPECT_LE(c.force_n.norm(), bound_n);
    EXPECT_TRUE(st.converged || !c.converged);
  }
  for (int m = 0; m < sim.num_meshes(); ++m) {
    Eigen::VectorXd u;
    sim.displacements(m, u);
    EXPECT_TRUE(u.allFinite()) << m;
  }
  std::vector<SlidingPairState> pairs;
  sim.sliding_pairs(kCylinder, pairs);
  for (const auto& p : pairs) {
    EXPECT_TRUE(std::isfinite(p.force_n));
    EXPECT_GE(p.force_n, 0.0);
  }
  if (st.converged) {
    EXPECT_LE(sim.sliding_penetration_m(), 1e-9 * std::abs(depth));
  }
}

TEST(interaction_sliding_stability, StiffnessRatio1e4) {
  for (double e_emb : {1.0e2, 1.0e10}) {
    SceneSpec spec = sliding_spec();
    spec.embedded_e_pa = e_emb;
    auto s = run(spec, {push_right(0.005)});
    EXPECT_TRUE(s.stats.converged) << e_emb;
    expect_sane(*s.sim, s.contacts, s.stats, 0.005, e_emb > 1e6 ? 1e4 * kBoundN : kBoundN);
  }
}

TEST(interaction_sliding_stability, NearlyIncompressible) {
  SceneSpec spec = sliding_spec();
  spec.nu = 0.499;
  auto s = run(spec, {push_right(0.005)});
  EXPECT_TRUE(s.stats.converged);
  expect_sane(*s.sim, s.contacts, s.stats, 0.005, kBoundN);
}

TEST(interaction_sliding_stability, StiffRatioNearlyIncompressibleLargeMotion) {
  SceneSpec spec = sliding_spec();
  spec.nu = 0.499;
  spec.embedded_e_pa = 1.0e10;
  auto sim = Simulation::build(testing::make_scene(spec));
  std::vector<ToolContact> c;
  StepStats st;
  // Deep push (30 % of the cube), a 10 cm jump through the body and back, withdrawal.
  for (double depth : {0.03, 0.1, 0.002, 0.102, 0.03, -0.002}) {
    sim->step({push_right(depth)}, c, st);
    expect_sane(*sim, c, st, depth, 1e4 * kBoundN);
  }
  EXPECT_FALSE(c[0].in_contact);
}

TEST(interaction_sliding_stability, TwoToolsAndToolInsideTheEmbeddedMesh) {
  auto sim = Simulation::build(testing::make_scene(sliding_spec()));
  std::vector<ToolContact> c;
  StepStats st;
  ToolPose inside;
  inside.tip_m = Vec3(0.05, 0.05, 0.05);
  inside.axis = Vec3::UnitX();
  sim->step({push_right(0.004), push_right(0.004), inside}, c, st);
  ASSERT_EQ(c.size(), 3u);
  expect_sane(*sim, c, st, 0.004, kBoundN);
}

// The LCP's inactive-set path (inverse of the constant sliding block) and the reference path
// (factor of the active rows) give the same step: tool force, contact stiffness, pair forces,
// over a path that presses, slides and releases (pivots both ways, factors kept between steps).
TEST(interaction_sliding, InactiveSetPathMatchesReferencePath) {
  SimulationOptions fast_opt, ref_opt;
  fast_opt.sliding_inactive_set_always = true;
  ref_opt.sliding_inactive_set = false;
  auto fast = Simulation::build(testing::make_scene(sliding_spec()), fast_opt);
  auto ref = Simulation::build(testing::make_scene(sliding_spec()), ref_opt);
  std::vector<ToolContact> cf, cr;
  StepStats sf, sr;
  std::vector<SlidingPairState> pf, pr;
  int compared = 0;
  for (int k = 0; k <= 40; ++k) {
    const double depth = 0.006 * std::sin(M_PI * k / 40.0);
    ToolPose pose = push_right(depth);
    pose.tip_m.y() += 0.01 * std::sin(0.3 * k);
    fast->step({pose}, cf, sf);
    ref->step({pose}, cr, sr);
    ASSERT_TRUE(sf.converged) << k;
    ASSERT_TRUE(sr.converged) << k;
    EXPECT_EQ(sf.sliding_active, sr.sliding_active) << k;
    const double fscale = std::max(cr[0].force_n.norm(), 1e-12);
    EXPECT_LE((cf[0].force_n - cr[0].force_n).norm(), 1e-8 * fscale) << k;
    const double kscale = std::max(cr[0].stiffness_n_per_m.norm(), 1e-12);
    EXPECT_LE((cf[0].stiffness_n_per_m - cr[0].stiffness_n_per_m).norm(), 1e-7 * kscale) << k;
    fast->sliding_pairs(kCylinder, pf);
    ref->sliding_pairs(kCylinder, pr);
    ASSERT_EQ(pf.size(), pr.size());
    double largest = 1e-300;
    for (const auto& p : pr) largest = std::max(largest, p.force_n);
    for (std::size_t i = 0; i < pf.size(); ++i)
      EXPECT_NEAR(pf[i].force_n, pr[i].force_n, 1e-8 * largest) << k << " pair " << i;
    EXPECT_LE(fast->sliding_penetration_m(), 1e-9 * std::max(depth, 1e-4)) << k;
    if (sr.sliding_active > 0) ++compared;
  }
  EXPECT_GT(compared, 20);
}

}  // namespace
// A SLIDING coupling serves viewers: the field snapshot (the server's field thread) gives every
// mesh, the sliding-embedded one included, the same displacements as the stepping-thread path,
// and the embedded mesh moves when the host pushes it through the sliding rows.
TEST(interaction_sliding, FieldSnapshotServesEveryMesh) {
  auto sim = Simulation::build(testing::make_scene(sliding_spec()));
  std::vector<ToolContact> c;
  StepStats st;
  sim->step({push_right(0.006)}, c, st);
  ASSERT_TRUE(c[0].in_contact);
  ASSERT_GT(st.sliding_active, 0);
  FieldSnapshot snap;
  sim->snapshot(snap);
  sim->step({push_right(0.001)}, c, st);  // a later step does not change the snapshot's fields
  for (int m = 0; m < sim->num_meshes(); ++m) {
    Eigen::VectorXd from_snapshot, now;
    sim->displacements(snap, m, from_snapshot);
    ASSERT_EQ(from_snapshot.size(), 3 * static_cast<Eigen::Index>(sim->mesh(m).num_vertices()));
    ASSERT_TRUE(from_snapshot.allFinite()) << sim->mesh_id(m);
    EXPECT_GT(from_snapshot.cwiseAbs().maxCoeff(), 1e-5) << sim->mesh_id(m) << " did not move";
    sim->displacements(m, now);  // the 1 mm step
    EXPECT_GT((from_snapshot - now).cwiseAbs().maxCoeff(), 1e-5) << sim->mesh_id(m);
  }
  // Stepped back to the snapshot's pose, the stepping-thread fields equal the snapshot's.
  sim->step({push_right(0.006)}, c, st);
  for (int m = 0; m < sim->num_meshes(); ++m) {
    Eigen::VectorXd from_snapshot, now;
    sim->displacements(snap, m, from_snapshot);
    sim->displacements(m, now);
    EXPECT_LE((from_snapshot - now).cwiseAbs().maxCoeff(), 1e-9 * now.cwiseAbs().maxCoeff())
        << sim->mesh_id(m);
  }
}

}  // namespace neurosim::interaction
