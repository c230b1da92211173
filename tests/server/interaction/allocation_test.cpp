// The step is State only: once warmed up (contact columns cached, workspace sized) it must not
// allocate. Counts operator new calls around step() on the stepping thread (the COROTATIONAL and
// NONLINEAR tiers' worker thread allocates in its Newton solves: not the 1 kHz step).
#include "server/interaction/contact_lcp.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include "cube_cylinder_fixtures.hpp"
#include "interaction_fixtures.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>
#include <cmath>
#include <cstdlib>
#include <new>
#include <vector>

#include "thread_allocation_counter.hpp"

namespace {
// This thread's count (the stepping thread's when called from it).
struct ThreadCount {
  long load() const { return neurosim::testing::allocations_on_this_thread(); }
} g_allocations;
}  // namespace

namespace neurosim::interaction {
namespace {

// pause: between steps (lets a tier worker publish new linearizations during the steps).
void expect_warm_step_does_not_allocate(const testing::SceneSpec& spec,
                                        std::chrono::milliseconds pause = {},
                                        const SimulationOptions& options = {}) {
  auto sim = Simulation::build(testing::make_scene(spec), options);
  std::vector<ToolPose> poses(2);
  auto set = [&](double d0, double d1) {
    poses[0].tip_m = Vec3(0.1 + spec.tip_radius_m - d0, 0.05, 0.05);
    poses[0].axis = Vec3::UnitX();
    poses[1].tip_m = Vec3(0.05, 0.1 + spec.tip_radius_m - d1, 0.06);
    poses[1].axis = Vec3::UnitY();
  };
  std::vector<ToolContact> contacts;
  StepStats stats;
  // Warm-up over the same path: columns of every touched node get cached (this allocates, which
  // also shows the counter works).
  const long at_build = g_allocations.load();
  for (int k = 0; k <= 10; ++k) {
    set(0.0005 * k, 0.0004 * k);
    sim->step(poses, contacts, stats);
  }
  ASSERT_TRUE(contacts[0].in_contact);
  ASSERT_TRUE(contacts[1].in_contact);
  EXPECT_GT(g_allocations.load() - at_build, 0);
  const long before = g_allocations.load();
  for (int k = 10; k >= 0; --k) {
    set(0.0005 * k, 0.0004 * k);
    sim->step(poses, contacts, stats);
    std::this_thread::sleep_for(pause);
  }
  if (sim->tier() != scene::Tier::kLinear) {
    EXPECT_GT(sim->tier_update_rate_hz(), 0.0);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

TEST(interaction_allocation, WarmStepDoesNotAllocate) {
  expect_warm_step_does_not_allocate(testing::SceneSpec{});
}

// COROTATIONAL and NONLINEAR: the step reads the worker's newest linearization (rotations,
// offsets, the deformed surface) and hands its forces over, without allocating. The rows are
// found on the worker's latest equilibrium, which lags the path by a thread-timed amount, so the
// nodes first touched on the way back vary from run to run: every column is computed at load
// here (the first touches of the other cases are covered by their warm-up).
TEST(interaction_allocation, WarmTierStepDoesNotAllocate) {
  for (const char* tier : {"NONLINEAR"}) {  // COROTATIONAL: withdrawn from scenes
    SCOPED_TRACE(tier);
    testing::SceneSpec spec;
    spec.tier = tier;
    SimulationOptions options;
    options.precompute_contact_columns = true;
    expect_warm_step_does_not_allocate(spec, std::chrono::milliseconds(100), options);
  }
}

// SLIDING: the sliding rows join the LCP (constant block, factor kept between steps).
TEST(interaction_allocation, WarmSlidingStepDoesNotAllocate) {
  testing::SceneSpec spec;
  spec.sliding = true;
  expect_warm_step_does_not_allocate(spec);
}

// SLIDING with an exposed embedded mesh (the cube/cylinder scene, the cylinder raised 20 mm out
// of the cube's top): the tip pressing its top, B's own columns and their sliding rows in the LCP.
TEST(interaction_allocation, WarmExposedSlidingStepDoesNotAllocate) {
  scene::Scene s = testing::cube_cylinder_at(0.105, true);
  s.mutable_couplings(0)->set_kind(scene::Coupling::SLIDING);
  auto sim = Simulation::build(scene::compile(s, testing::cube_cylinder_path().string()));
  std::vector<ToolPose> poses(1);
  std::vector<ToolContact> contacts;
  StepStats stats;
  // Over the cylinder's top (its axis at x = 50 mm, z = 105 mm; radius 15 mm; the 3 mm tip).
  auto set = [&](double d) {
    poses[0].tip_m = Vec3(0.05, 0.05, 0.12 + 0.003 - d);
    poses[0].axis = Vec3::UnitZ();
  };
  const long at_build = g_allocations.load();
  for (int k = 0; k <= 10; ++k) {
    set(0.0001 * k);
    sim->step(poses, contacts, stats);
  }
  ASSERT_TRUE(contacts[0].in_contact);
  EXPECT_GT(stats.sliding_rows, 0);
  EXPECT_GT(g_allocations.load() - at_build, 0);
  const long before = g_allocations.load();
  for (int k = 10; k >= 0; --k) {
    set(0.0001 * k);
    sim->step(poses, contacts, stats);
  }
  EXPECT_EQ(g_allocations.load() - before, 0);
}

// The LCP's inactive-set path for a constant leading block (ContactLcp::set_constant_block): no
// allocation per solve and per contact stiffness, with new trailing rows every solve (coupling
// columns not cached yet), pivots both ways, and a switch to the reference path and back.
TEST(interaction_allocation, ConstantBlockLcpDoesNotAllocate) {
  const int ns = 50, cap = 62, dim = 70;
  Eigen::MatrixXd rows(cap, dim);
  for (int i = 0; i < cap; ++i)
    for (int j = 0; j < dim; ++j) rows(i, j) = std::sin(1.0 + 0.37 * i * j + 0.11 * i);
  auto fill = [&](int step, Eigen::MatrixXd& w) {
    for (int i = ns; i < cap; ++i)
      for (int j = 0; j < dim; ++j) rows(i, j) = std::sin(0.3 * step + 0.37 * i * j + 0.7 * i);
    w.noalias() = rows * rows.transpose() / dim;
    w.diagonal().array() += 0.05;
    w *= 1e-4;
  };
  Eigen::MatrixXd w(cap, cap);
  fill(0, w);
  Eigen::VectorXd d(cap), lam = Eigen::VectorXd::Zero(cap);
  std::vector<char> warm(cap, 1);
  ContactLcp fast, hybrid;
  fast.reserve(cap);
  hybrid.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  ASSERT_TRUE(hybrid.set_constant_block(w, ns));
  LcpOptions options;
  options.tolerance = 1e-12;
  options.max_iterations = 2000;
  int inactive_path = 0;
  const Eigen::Vector3d normal(0.6, 0.0, 0.8);
  auto run = [&](ContactLcp& lcp, int step) {
    fill(step, w);
    const double shift = step % 20 < 10 ? 4e-4 : -6e-4;  // many leading rows pushed, then few
    for (int i = 0; i < cap; ++i) d[i] = 1e-3 * std::sin(0.9 * i + 0.2 * step) + shift;
    for (int i = 0; i < cap; ++i) warm[i] = i < ns ? (lam[i] > 0.0 ? 1 : 0) : d[i] > 0.0;
    const int n = ns + 4 + step % 8;
    options.path = &lcp == &fast ? LcpPath::inactive_set : LcpPath::automatic;
    const LcpResult r = lcp.solve(LcpProblem{&w, &d, n, ns, &warm}, options, lam);
    inactive_path += lcp.last_solve_inactive_set() ? 1 : 0;
    if (!r.converged) return false;
    const Eigen::Matrix3d k = lcp.contact_stiffness(
        ns, [&](int row) -> const Eigen::Vector3d* { return row % 2 == 0 ? &normal : nullptr; });
    return k.allFinite();
  };
  for (ContactLcp* lcp : {&fast, &hybrid}) {
    for (int step = 0; step < 3; ++step) ASSERT_TRUE(run(*lcp, step));
    const long before = g_allocations.load();
    bool ok = true;
    for (int step = 3; step < 60; ++step) ok = run(*lcp, step) && ok;
    EXPECT_EQ(g_allocations.load() - before, 0);
    EXPECT_TRUE(ok);
    // fast: every solve on the inactive set; hybrid: both paths.
    if (lcp == &fast) {
      EXPECT_EQ(inactive_path, 60);
    } else {
      EXPECT_GT(inactive_path, 5);
      EXPECT_LT(inactive_path, 55);
    }
    inactive_path = 0;
  }
}

}  // namespace
}  // namespace neurosim::interaction
