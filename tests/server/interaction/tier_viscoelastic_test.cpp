// Relaxing tissue in the NONLINEAR tier (quasi-linear viscoelasticity in the tier's equilibrium,
// tier_equilibrium.hpp): a block pressed by the tool, the step and the synchronous updates
// (deterministic). Stepping one pose again at one time iterates the multirate fixed point at that
// instant (a step at the time of the last one replaces it), so:
//  - a small press held: the converged force at each time is the elastic one times g(t), the
//    Prony relaxation (analytic; 1e-3 at small strain);
//  - a 1 mm press (5 % of the block) held with one step per ms, then per 10 ms (the fixed point
//    moving in time, one update per step): the force converges to the relaxed answer, the same
//    press on the hyperelastic block with every modulus scaled by g_inf (exact for QLV);
//  - the same with the worker on its own thread (the server's mode, coarse uneven update times);
//  - relaxation times of 1 ms and 1000 s and a pause of 1e4 s stay finite and bounded;
//  - the anp-tet and smoothed-tet elements are refused naming the mesh (not implemented).
#include "server/interaction/simulation.hpp"
#include "visco_block_fixtures.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <chrono>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::interaction {
namespace {

using visco_testing::BlockSpec;
using visco_testing::press;

// The block in the NONLINEAR tier, its worker's updates inside each step (deterministic).
std::unique_ptr<Simulation> block(BlockSpec b, SimulationOptions o = {}) {
  b.tier = "NONLINEAR";
  o.tier_worker_thread = false;  // deterministic: the update runs inside each step
  o.tier_newton_tolerance = 1e-12;
  return visco_testing::build_block(b, o);
}

const std::vector<fem::PronyTerm> kTerms{{0.3, 0.05}, {0.2, 0.5}};

double relaxation(const std::vector<fem::PronyTerm>& terms, double t) {
  fem::Viscoelastic v;
  v.terms = terms;
  return v.relaxation(t);
}

// Steps `pose` at time t until the force settles (the fixed point at that instant); returns it.
Vec3 settle_at(Simulation& sim, double t, const std::vector<ToolPose>& pose, int max_steps = 200) {
  std::vector<ToolContact> c;
  StepStats st;
  Vec3 prev = Vec3::Constant(1e300);
  for (int k = 0; k < max_steps; ++k) {
    sim.step_at(t, pose, c, st);
    if (c[0].in_contact && (c[0].force_n - prev).norm() <= 1e-12 * c[0].force_n.norm()) break;
    prev = c[0].force_n;
  }
  return c[0].in_contact ? c[0].force_n : Vec3::Zero();
}

TEST(interaction_tier_viscoelastic, HeldSmallPressRelaxesAsTheKernel) {
  auto sim = block({kTerms});
  const auto pose = press(1e-6);
  const double f0 = settle_at(*sim, 0.0, pose).z();
  ASSERT_GT(f0, 0.0);
  double worst = 0.0, t = 0.0;
  for (int k = 1; k <= 250; ++k) {  // 2.5 s = 5 tau_max: 10 ms per time
    t = 0.01 * k;
    const double f = settle_at(*sim, t, pose).z();
    const double err = std::abs(f / f0 - relaxation(kTerms, t));
    worst = std::max(worst, err);
    ASSERT_LT(err, 1e-3) << "t = " << t << " s";
  }
  std::printf("NONLINEAR, 1 um press held: F(t) / F(0) against g(t) within %.2e over %.1f s\n", worst, t);
}

TEST(interaction_tier_viscoelastic, HeldPressConvergesToTheRelaxedAnswer) {
  const double depth = 0.001;
  // The relaxed answer: the hyperelastic block with E g_inf (nu unchanged: every modulus scaled).
  const double g_inf = 1.0 - 0.3 - 0.2;
  auto relaxed = block({{}, 3000.0 * g_inf});
  const Vec3 f_relaxed = settle_at(*relaxed, 0.0, press(depth), 400);
  auto elastic = block({});
  const Vec3 f_elastic = settle_at(*elastic, 0.0, press(depth), 400);
  ASSERT_GT(f_relaxed.z(), 0.0);

  // The press in 100 ms (1 ms steps), held: 1 ms steps to 1 s, then 10 ms steps to 10 s = 20
  // tau_max; one step (one update) per time: the fixed point moves in time.
  auto sim = block({kTerms});
  std::vector<ToolContact> c;
  StepStats st;
  double t = 0.0, f_end_of_press = 0.0;
  for (int k = 0; t < 10.0; ++k) {
    t = k < 1000 ? 1e-3 * k : 1.0 + 0.01 * (k - 1000);
    sim->step_at(t, press(depth * std::min(1.0, t / 0.1)), c, st);
    ASSERT_TRUE(c[0].force_n.allFinite()) << "t = " << t;
    if (k == 100) f_end_of_press = c[0].force_n.z();
  }
  ASSERT_TRUE(c[0].in_contact);
  const double rel = (c[0].force_n - f_relaxed).norm() / f_relaxed.norm();
  EXPECT_LT(rel, 1e-6);
  EXPECT_GT(f_end_of_press, 1.2 * f_relaxed.z());  // it did relax
  std::printf("NONLINEAR, 1 mm press: elastic %.6f N, at the end of a 100 ms press %.6f N, after 10 s "
              "%.8f N, relaxed answer (E g_inf) %.8f N: %.2e apart\n",
              f_elastic.z(), f_end_of_press, c[0].force_n.z(), f_relaxed.z(), rel);
}

// The server's mode: the worker on its own thread takes the newest loads, so its updates' times
// are whatever sample times it finds (coarse, uneven steps); a held press still ends at the
// relaxed answer. The press in 100 sample-ms, held to 20 s = 40 tau_max (10 sample-ms per step,
// 1 ms apart in real time: a worker starved for seconds still ends relaxed), then stepped at 20 s
// until the force is still for a second (at most a minute).
TEST(interaction_tier_viscoelastic, WorkerThreadReachesTheRelaxedAnswer) {
  const double depth = 0.001;
  auto relaxed = block({{}, 3000.0 * (1.0 - 0.3 - 0.2)});
  const Vec3 f_relaxed = settle_at(*relaxed, 0.0, press(depth), 400);
  SimulationOptions o;
  o.tier_newton_tolerance = 1e-12;  // worker thread (the default)
  auto sim = visco_testing::build_block({kTerms, 3000.0, "NONLINEAR"}, o);
  std::vector<ToolContact> c;
  StepStats st;
  double t = 0.0;
  for (int k = 0; t < 20.0; ++k) {
    t = k < 100 ? 1e-3 * k : 0.1 + 0.01 * (k - 100);
    sim->step_at(t, press(depth * std::min(1.0, t / 0.1)), c, st);
    std::this_thread::sleep_for(std::chrono::microseconds(1000));
  }
  Vec3 prev = Vec3::Zero();
  const auto t0 = std::chrono::steady_clock::now();
  auto still_since = t0;
  while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(60)) {
    sim->step_at(t, press(depth), c, st);
    const auto now = std::chrono::steady_clock::now();
    if ((c[0].force_n - prev).norm() > 1e-11 * c[0].force_n.norm()) still_since = now;
    if (now - still_since > std::chrono::seconds(1)) break;
    prev = c[0].force_n;
    std::this_thread::sleep_for(std::chrono::microseconds(1000));
  }
  ASSERT_TRUE(c[0].in_contact);
  const double rel = (c[0].force_n - f_relaxed).norm() / f_relaxed.norm();
  std::printf("worker thread: after %.2f s held %.8f N, relaxed answer %.8f N: %.2e apart\n", t,
              c[0].force_n.z(), f_relaxed.z(), rel);
  EXPECT_LT(rel, 1e-6);
}

TEST(interaction_tier_viscoelastic, ExtremeRelaxationTimesStayFinite) {
  const std::vector<fem::PronyTerm> terms{{0.5, 1e-3}, {0.3, 1e3}};
  auto sim = block({terms});
  const auto pose = press(0.0005);
  const double f0 = settle_at(*sim, 0.0, pose).z();
  ASSERT_GT(f0, 0.0);
  std::vector<double> times;
  for (int k = 1; k <= 100; ++k) times.push_back(1e-3 * k);
  times.push_back(1e4);
  times.push_back(1e4 + 1e-3);
  for (double t : times) {
    const double f = settle_at(*sim, t, pose).z();
    ASSERT_TRUE(std::isfinite(f)) << "t = " << t;
    EXPECT_LE(f, f0 * (1.0 + 1e-6)) << "t = " << t;
    EXPECT_GE(f, f0 * 0.2 * (1.0 - 1e-3)) << "t = " << t;
  }
}

// The contact options (contact_spread, contact_smooth_normals, contact_near_field): the near
// field in series relaxes with the mesh's kernel in the relaxation form (the tier's equilibrium
// relaxes with the displacement held), so a held press follows g(t) at 10 ms steps and after a
// jump from 0.1 s to 1e4 s (a 1000 s term) ends at g(1e4 s) F(0) (the creep form gave 0.163 F(0)
// against 0.200 there).
TEST(interaction_tier_viscoelastic, NearFieldRelaxesAsTheKernel) {
  SimulationOptions o;
  o.contact_spread = 1.0;
  o.contact_smooth_normals = true;
  o.contact_near_field = true;
  for (const auto& terms : {kTerms, std::vector<fem::PronyTerm>{{0.5, 1e-3}, {0.3, 1e3}}}) {
    auto sim = block({terms}, o);
    const auto pose = press(0.0005);
    const double f0 = settle_at(*sim, 0.0, pose).z();
    ASSERT_GT(f0, 0.0);
    double worst = 0.0;
    for (double t : {0.01, 0.02, 0.05, 0.1, 1e4}) {
      const double err = std::abs(settle_at(*sim, t, pose).z() / f0 - relaxation(terms, t));
      worst = std::max(worst, err);
      EXPECT_LT(err, 1e-3) << "t = " << t << " s";
    }
    std::printf("NONLINEAR, contact options, 0.5 mm press held: F(t) / F(0) against g(t) within "
                "%.2e\n", worst);
  }
}

TEST(interaction_tier_viscoelastic, RefusesWhatIsNotImplementedNamingTheMesh) {
  for (const char* element : {"anp-tet", "smoothed-tet"}) {
    try {
      auto sim = block({kTerms, 3000.0, "NONLINEAR", element});
      ADD_FAILURE() << element << " accepted";
    } catch (const std::exception& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("block"), std::string::npos) << what;
      EXPECT_NE(what.find("viscoelastic"), std::string::npos) << what;
      EXPECT_NE(what.find(element), std::string::npos) << what;
    }
  }
}

}  // namespace
}  // namespace neurosim::interaction
