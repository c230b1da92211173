// The COROTATIONAL and NONLINEAR tiers in the Simulation (tier_equilibrium.hpp): a held tool
// converges to the tier's own contact equilibrium. Checked against references outside the
// multirate loop: a fresh fem::EquilibriumSolver solved from rest under the converged contact
// forces (the field must be that equilibrium), and the contact conditions evaluated on that
// field (no penetration anywhere, touching where the tool pushes).
#include "server/interaction/tier_equilibrium.hpp"

#include "interaction_fixtures.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/contact_surface.hpp"
#include "server/interaction/tool_geometry.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "thread_allocation_counter.hpp"

namespace neurosim::interaction {
namespace {

using testing::push_right;
using testing::SceneSpec;

struct Held {
  std::unique_ptr<Simulation> sim;
  std::vector<ToolContact> contacts;
  int steps{0};
  double last_change{0.0};  // |f_k - f_k-1| / |f_k| of the last step
};

// Converged: the force changes by less than this between steps (relative). The fixed point is
// reached to about the Newton tolerance of the updates (1e-12 here).
constexpr double kSettled = 1e-11;

// Steps one pose until the force stops changing (synchronous updates: deterministic), with the
// default rows or, `barycentric_rows`, the rows on the touched triangles' nodes by barycentric
// weights (no spread, no smooth normals, no near field).
Held hold(const SceneSpec& spec, const ToolPose& pose, int max_steps = 60,
          bool barycentric_rows = false) {
  SimulationOptions o;
  o.tier_worker_thread = false;
  o.tier_newton_tolerance = 1e-12;
  if (barycentric_rows) {
    o.contact_spread = 0.0;
    o.contact_smooth_normals = false;
    o.contact_near_field = false;
  }
  Held h;
  h.sim = Simulation::build(testing::make_scene(spec), o);
  StepStats st;
  Vec3 prev = Vec3::Constant(1e300);
  for (h.steps = 1; h.steps <= max_steps; ++h.steps) {
    h.sim->step({pose}, h.contacts, st);
    const Vec3 f = h.contacts[0].force_n;
    h.last_change = (f - prev).norm() / std::max(f.norm(), 1e-300);
    prev = f;
    if (h.last_change < kSettled) break;
  }
  return h;
}

// The equilibrium of the simulation's host and tied meshes for the last step's contact forces,
// solved from rest in load increments by a solver of its own.
Eigen::VectorXd reference_equilibrium(const Simulation& sim, fem::Tier tier,
                                      const fem::Material& host_material) {
  const int host = 0;
  const CoupledBody& body = *sim.body_of(host);
  fem::EquilibriumSolver solver(
      equilibrium_definition(body, host_material, sim.fixed_nodes(host), tier));
  std::vector<int> slots;
  std::vector<Vec3> forces;
  sim.last_contact_forces(host, slots, forces);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
  for (std::size_t k = 0; k < slots.size(); ++k)
    f.segment<3>(3 * body.contact_nodes()[slots[k]]) += forces[k];
  return solver.solve(f).displacement_m;
}

class Tiers : public ::testing::TestWithParam<const char*> {};

// A 15 mm press (15 % of the cube's edge) held still: the force converges; the field is the
// tier's equilibrium under that force (1e-8); on that field no surface node enters the tool and
// the nearest touches it (1e-7 of the press); the tier differs from LINEAR. The rows are
// barycentric: node-to-surface contact with the tool as master (CalculiX's), which keeps the
// nodes out of the sphere, not the faces between them. A triangle whose nodes are out of it
// enters it by at most the sag of its circumcircle, r - sqrt(r^2 - rho^2) (the foot of the
// centre on its plane, inside it, is within rho of a node), checked too: this cube's 12 mm cells
// under the 15 mm tip sag up to 3.8 mm into it, under LINEAR's rows as under the tiers' (the
// 60-degree tier rows met "no triangle inside" by pressing the nodes under the tip to a plane,
// a flat punch: a vertex twice as hard as a face; bench/RESULTS.md, "The tiers' exit point from
// the deformed point"). The default rows spread each row's load over a local edge length and
// hold the patch's load-weighted mean at the tip, so there even a node under the tip's centre
// may enter the sphere.
TEST_P(Tiers, HeldPressConvergesToTheTierContactEquilibrium) {
  SceneSpec spec;
  spec.tier = GetParam();
  const fem::Tier tier = *fem::parse_tier(GetParam());
  const double press = 0.015;
  const ToolPose pose = push_right(press);
  const Held h = hold(spec, pose, 60, true);
  ASSERT_LE(h.last_change, kSettled) << "not converged after " << h.steps << " steps";
  const Simulation& sim = *h.sim;
  EXPECT_EQ(sim.tier(), tier);
  const ToolContact& c = h.contacts[0];
  ASSERT_TRUE(c.in_contact);
  ASSERT_TRUE(c.force_n.allFinite());

  // The field is the tier's equilibrium for the converged forces.
  fem::Material host_material{1.0e6, 0.4, "host"};
  host_material.element = fem::kDefaultSceneElement;  // the scene names no element
  const Eigen::VectorXd ref = reference_equilibrium(sim, tier, host_material);
  Eigen::VectorXd u_host, u_cyl;
  sim.displacements(0, u_host);
  sim.displacements(1, u_cyl);
  ASSERT_EQ(ref.size(), u_host.size() + u_cyl.size());
  const double scale = ref.cwiseAbs().maxCoeff();
  EXPECT_LE((u_host - ref.head(u_host.size())).cwiseAbs().maxCoeff(), 1e-8 * scale);
  EXPECT_LE((u_cyl - ref.tail(u_cyl.size())).cwiseAbs().maxCoeff(), 1e-8 * scale);
  EXPECT_LE(sim.tie_residual_m(), 1e-12 * scale);

  // Contact conditions on that field: the tool's sphere against the deformed nodes of the
  // pressed face (x = 0.1): none enters it, and the closest one touches it (the contact is
  // active), to 1e-7 of the press (the row compliance in series is 1e-8 relative); no triangle
  // enters it by more than its circumcircle's sag.
  std::vector<int> slots;
  std::vector<Vec3> forces;
  sim.last_contact_forces(0, slots, forces);
  ASSERT_FALSE(slots.empty());
  const mesh::TetMesh& host = sim.mesh(0);
  const double r = spec.tip_radius_m;
  double nearest = std::numeric_limits<double>::infinity();
  for (const auto& t : host.surface()) {
    std::array<Vec3, 3> x;
    bool pressed = true;
    for (int k = 0; k < 3; ++k) {
      pressed = pressed && host.vertices()[t[k]].x() > 0.1 - 1e-9;
      x[k] = host.vertices()[t[k]] + u_host.segment<3>(3 * t[k]);
    }
    if (!pressed) continue;
    for (int k = 0; k < 3; ++k) nearest = std::min(nearest, (x[k] - pose.tip_m).norm());
    const Vec3 a = x[1] - x[0], b = x[2] - x[0];
    const double twice_area = a.cross(b).norm();
    ASSERT_GT(twice_area, 0.0);
    const double rho = a.norm() * b.norm() * (x[2] - x[1]).norm() / (2.0 * twice_area);
    const double least = std::sqrt(std::max(0.0, r * r - rho * rho));
    EXPECT_GE((closest_on_triangle(pose.tip_m, x).point_m - pose.tip_m).norm(),
              least - 1e-7 * press);
  }
  EXPECT_GE(nearest, r - 1e-7 * press);
  EXPECT_LE(nearest, r + 1e-7 * press);

  // Not linear in disguise: the linear tier's force differs.
  SceneSpec lin = spec;
  lin.tier = "LINEAR";
  const Held hl = hold(lin, pose, 2, true);
  const double fl = hl.contacts[0].force_n.norm(), ft = c.force_n.norm();
  std::printf("%s: 15 mm press, force %.6g N (LINEAR %.6g N, %+.2f %%), converged in %d steps\n",
              GetParam(), ft, fl, 100.0 * (ft - fl) / fl, h.steps);
  EXPECT_GT(std::abs(ft - fl), 1e-3 * fl);
}

// A small press: every tier agrees with LINEAR (consistency of the linearization).
TEST_P(Tiers, SmallPressAgreesWithLinear) {
  SceneSpec spec;
  spec.tier = GetParam();
  const ToolPose pose = push_right(1e-7);
  const Held h = hold(spec, pose);
  SceneSpec lin = spec;
  lin.tier = "LINEAR";
  const Held hl = hold(lin, pose, 2);
  const Vec3 fl = hl.contacts[0].force_n;
  ASSERT_GT(fl.norm(), 0.0);
  EXPECT_LE((h.contacts[0].force_n - fl).norm(), 1e-5 * fl.norm());
}

// The worker thread (the server's mode) reaches the same answer as the synchronous updates.
TEST_P(Tiers, WorkerThreadReachesTheSynchronousAnswer) {
  for (const char* element : {"", "smoothed-tet"}) {
  SceneSpec spec;
  spec.tier = GetParam();
  spec.element = element;
  const ToolPose pose = push_right(0.01);
  const Held sync = hold(spec, pose);
  SimulationOptions o;
  o.tier_newton_tolerance = 1e-12;
  auto sim = Simulation::build(testing::make_scene(spec), o);  // worker thread
  std::vector<ToolContact> c;
  StepStats st;
  Vec3 prev = Vec3::Zero();
  // Settled: at least one update done and the force still for a second (the step runs at about
  // 1 kHz, the worker as fast as it goes); at most a minute.
  const auto t0 = std::chrono::steady_clock::now();
  auto still_since = t0;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60)) {
    sim->step({pose}, c, st);
    const auto now = std::chrono::steady_clock::now();
    if ((c[0].force_n - prev).norm() > kSettled * c[0].force_n.norm() ||
        sim->tier_update_rate_hz() == 0.0)
      still_since = now;
    if (now - still_since > std::chrono::seconds(1)) break;
    prev = c[0].force_n;
    std::this_thread::sleep_for(std::chrono::microseconds(1000));
  }
  const Vec3 fs = sync.contacts[0].force_n;
  std::printf("worker vs synchronous, element '%s': %.9g N vs %.9g N\n", element,
              c[0].force_n.norm(), fs.norm());
  EXPECT_LE((c[0].force_n - fs).norm(), 1e-9 * fs.norm())
      << element << ": " << c[0].force_n.transpose() << " vs " << fs.transpose();
  EXPECT_GT(sim->tier_update_rate_hz(), 0.0);
  EXPECT_TRUE(std::isfinite(sim->tier_update_rate_hz()));
  }
}

// COROTATIONAL is withdrawn from scenes (fem/served_tiers.hpp): a scene naming it is refused.
INSTANTIATE_TEST_SUITE_P(interaction_tier, Tiers, ::testing::Values("NONLINEAR"));

TEST(interaction_tier, CorotationalSceneIsRefusedNamingTheAlternatives) {
  SceneSpec spec;
  spec.tier = "COROTATIONAL";
  try {
    Simulation::build(testing::make_scene(spec));
    FAIL() << "a COROTATIONAL scene was built";
  } catch (const std::exception& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("effects.tier"), std::string::npos) << msg;
    EXPECT_NE(msg.find("withdrawn"), std::string::npos) << msg;
    EXPECT_NE(msg.find("LINEAR"), std::string::npos) << msg;
    EXPECT_NE(msg.find("NONLINEAR"), std::string::npos) << msg;
  }
}

// What the non-linear tiers do not implement is refused at load, naming the tier and the
// coupling; never run as another tier or another coupling.
TEST(interaction_tier, SlidingAndIterativeAreRefusedOutsideLinear) {
  for (const char* tier : {"NONLINEAR"}) {
    for (int variant = 0; variant < 2; ++variant) {
      SceneSpec spec;
      spec.tier = tier;
      spec.sliding = variant == 0;
      spec.iterative = variant == 1;
      try {
        Simulation::build(testing::make_scene(spec));
        FAIL() << tier << " variant " << variant << " was built";
      } catch (const std::runtime_error& e) {
        const std::string msg = e.what();
        EXPECT_NE(msg.find(tier), std::string::npos) << msg;
        EXPECT_NE(msg.find("test.scene"), std::string::npos) << msg;
        EXPECT_NE(msg.find(variant == 0 ? "SLIDING" : "ITERATIVE"), std::string::npos) << msg;
      }
    }
  }
}

// The linear tier has no equilibrium to update: TierEquilibrium refuses it.
TEST(interaction_tier, TierEquilibriumRefusesLinear) {
  auto sim = Simulation::build(testing::make_scene(SceneSpec{}));
  TierEquilibriumDefinition d;
  d.body = sim->body_of(0);
  d.host_material = fem::Material{1.0e6, 0.4, "host"};
  d.host_fixed_nodes = sim->fixed_nodes(0);
  d.tier = fem::Tier::kLinear;
  EXPECT_THROW(TierEquilibrium{d}, std::invalid_argument);
}

// The linearization's C R^T f* from the loaded slots' compliance columns (kept, evicted when
// over the budget) equals the coupled solve of the host for those forces (budget 0) to 1e-10 of
// its size, on the tied cube in NONLINEAR with loads that rotate the nodes under them by 1-3
// degrees (|R - I| 0.03-0.08) and displace them by 1-3 mm, over loads that keep, add, drop, return to and exceed the kept slots;
// and a held load's linearization allocates nothing.
TEST(interaction_tier, ColumnLinearizationEqualsTheCoupledSolve) {
  SceneSpec spec;
  spec.tier = "NONLINEAR";
  auto sim = Simulation::build(testing::make_scene(spec));
  const CoupledBody& body = *sim->body_of(0);
  ASSERT_FALSE(body.ties().empty());
  TierEquilibriumDefinition d;
  d.body = &body;
  d.host_material = fem::Material{1.0e6, 0.4, "host"};
  d.host_material.element = fem::kDefaultSceneElement;
  d.host_fixed_nodes = sim->fixed_nodes(0);
  d.tier = fem::Tier::kNonlinear;
  d.newton.tolerance = 1e-12;
  d.column_budget_bytes = 0;
  TierEquilibrium solved(d);
  EXPECT_EQ(solved.column_capacity(), 0u);
  d.column_budget_bytes = TierEquilibriumDefinition{}.column_budget_bytes;
  TierEquilibrium kept(d);
  const std::size_t per_slot = sizeof(double) * 9 * body.contact_nodes().size();
  d.column_budget_bytes = 6 * per_slot + per_slot / 2;  // six slots
  TierEquilibrium small(d);
  ASSERT_EQ(small.column_capacity(), 6u);
  ASSERT_GE(kept.column_capacity(), 20u);

  // The contact slots nearest the middle of the cube's +x face, nearest first.
  const auto& nodes = body.contact_nodes();
  const auto& x = body.host().vertices();
  std::vector<int> near(nodes.size());
  for (std::size_t s = 0; s < near.size(); ++s) near[s] = static_cast<int>(s);
  const Vec3 centre(0.1, 0.05, 0.05);
  std::sort(near.begin(), near.end(), [&](int a, int b) {
    return (x[nodes[a]] - centre).norm() < (x[nodes[b]] - centre).norm();
  });
  ASSERT_GE(near.size(), 12u);
  // Each load: slots near[i] for i in `which`, 10 N each inward and some sideways.
  auto load_on = [&](std::initializer_list<int> which) {
    TierLoad l;
    for (int i : which) {
      const int s = near[static_cast<std::size_t>(i)];
      l.slots.push_back(s);
      l.forces_n.push_back(-10.0 * body.contact_normals()[s] + Vec3(0.0, 1.0 * (i % 3), 0.8));
    }
    return l;
  };
  const std::vector<TierLoad> loads = {
      load_on({0, 1, 2, 3}),              // four slots
      load_on({0, 1, 2, 3}),              // held
      load_on({2, 3, 4, 5}),              // two new
      load_on({6, 7, 8, 9}),              // four new: the small one evicts the oldest four
      load_on({0, 1, 2, 3}),              // back where it started
      load_on({0, 1, 2, 3, 4, 5, 6, 7}),  // more than six slots: the small one solves
      load_on({1, 2}),
  };
  TierLinearization ls, lk, lm;
  double worst = 0.0;
  for (std::size_t n = 0; n < loads.size(); ++n) {
    SCOPED_TRACE("load " + std::to_string(n));
    solved.update(loads[n], ls);
    kept.update(loads[n], lk);
    small.update(loads[n], lm);
    ASSERT_EQ(ls.u_m.size(), lk.u_m.size());
    // R C R^T f*'s size: u* - u0 at the slots, and how far the rotations are from I.
    double scale = 0.0, turn = 0.0;
    for (std::size_t s = 0; s < ls.offset_m.size(); ++s) {
      const int v = nodes[s];
      scale = std::max(scale, (ls.u_m.segment<3>(3 * v) - ls.offset_m[s]).cwiseAbs().maxCoeff());
      turn = std::max(turn, (ls.rotation[s] - Eigen::Matrix3d::Identity()).norm());
    }
    ASSERT_GT(scale, 0.0);
    std::printf("load %zu: R C R^T f* up to %.3g m, |R - I| up to %.3g\n", n, scale, turn);
    EXPECT_GT(turn, 2e-2);  // the nodes under the load rotate
    EXPECT_LE((ls.u_m - lk.u_m).cwiseAbs().maxCoeff(), 1e-14 * ls.u_m.cwiseAbs().maxCoeff());
    EXPECT_LE((ls.u_m - lm.u_m).cwiseAbs().maxCoeff(), 1e-14 * ls.u_m.cwiseAbs().maxCoeff());
    for (std::size_t s = 0; s < ls.offset_m.size(); ++s) {
      const double dk = (ls.offset_m[s] - lk.offset_m[s]).cwiseAbs().maxCoeff();
      const double dm = (ls.offset_m[s] - lm.offset_m[s]).cwiseAbs().maxCoeff();
      worst = std::max(worst, std::max(dk, dm) / scale);
      ASSERT_LE(dk, 1e-10 * scale) << "slot " << s;
      ASSERT_LE(dm, 1e-10 * scale) << "slot " << s;
    }
  }
  std::printf("largest offset difference, columns vs coupled solve: %.3g of R C R^T f*\n", worst);
  EXPECT_EQ(solved.linearization_solves(), loads.size());
  EXPECT_EQ(kept.linearization_solves(), 0u);
  EXPECT_EQ(kept.columns_solved(), 10u);  // slots 0-9, each once
  EXPECT_EQ(kept.columns_evicted(), 0u);
  EXPECT_EQ(small.linearization_solves(), 1u);  // the eight-slot load
  EXPECT_LE(small.columns_kept(), 6u);
  EXPECT_GE(small.columns_evicted(), 4u);
  EXPECT_GT(small.columns_solved(), 10u);  // some of slots 0-3 again after their eviction
  EXPECT_EQ(small.columns_solved() - small.columns_evicted(), small.columns_kept());

  // A held load's linearization (the last one's) allocates nothing; one on new slots does (their
  // columns: this shows the counter counts).
  kept.linearize(loads.back(), lk);
  long before = neurosim::testing::allocations_on_this_thread();
  kept.linearize(loads.back(), lk);
  kept.linearize(loads.back(), lk);
  EXPECT_EQ(neurosim::testing::allocations_on_this_thread() - before, 0);
  const TierLoad fresh = load_on({10, 11});
  before = neurosim::testing::allocations_on_this_thread();
  kept.linearize(fresh, lk);
  EXPECT_GT(neurosim::testing::allocations_on_this_thread() - before, 0);
}

}  // namespace
}  // namespace neurosim::interaction
