// The bundled viscoelastic brain (scenes/brain_viscoelastic.scene: Miller's relaxation, the
// artery tied and elastic) in the stability suite: thousands of 1 kHz steps of presses, holds,
// a slide and a release at the demo's press point. Every step converges and stays finite; under
// the held press the force only falls and ends between the relaxed and the instantaneous
// answers (g(t) of the scene's kernel bounds it from below); a quick press needs more force than
// a slow one to the same depth; after the release nothing is left pushing on the tool.
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

namespace neurosim::interaction {
namespace {

// The demo's press: a point of the right lateral surface and its outward normal.
const Vec3 kOrigin(0.1605, 0.1125, 0.0787);
const Vec3 kUp = Vec3(0.963, 0.176, 0.202).normalized();
constexpr double kDt = 1e-3;

struct BrainRun {
  std::unique_ptr<Simulation> sim;
  std::vector<ToolPose> poses{1};
  std::vector<ToolContact> contacts;
  StepStats stats;
  double t{0.0};
  double tip_radius_m{0.0};

  // Tip `depth_m` into the surface (its sphere touching at 0), shaft along the normal.
  double step(double depth_m, const Vec3& offset = Vec3::Zero()) {
    poses[0].tip_m = kOrigin + offset + (tip_radius_m - depth_m) * kUp;
    poses[0].axis = kUp;
    sim->step_at(t, poses, contacts, stats);
    t += kDt;
    EXPECT_TRUE(stats.converged) << "t = " << t;
    EXPECT_TRUE(contacts[0].force_n.allFinite()) << "t = " << t;
    return contacts[0].force_n.dot(kUp);
  }
};

BrainRun make_run(const scene::Model& model) {
  BrainRun r;
  SimulationOptions o;
  o.compliance_cache_dir = neurosim::testing::shared_cache_dir().string();  // factored once a run
  r.sim = Simulation::build(model, o);
  r.tip_radius_m = model.tools.at(0).tip_radius_m;
  return r;
}

TEST(interaction_viscoelastic_brain, PressHoldSlideReleaseStaysStableAndRelaxes) {
  const scene::Model model =
      scene::load_model(neurosim::testing::source_dir() / "scenes" / "brain_viscoelastic.scene");
  const auto& v = model.meshes.at(0).material.viscoelastic;
  ASSERT_EQ(v.terms.size(), 2u);
  ASSERT_FALSE(model.warnings.empty());  // the elastic artery tied to the relaxing brain
  BrainRun r = make_run(model);
  const double depth = 0.004;
  // Press 4 mm in 0.2 s, hold 3 s.
  double f_peak = 0.0;
  for (int k = 0; k <= 200; ++k) f_peak = r.step(depth * k / 200);
  const double t_hold = r.t;
  double f_prev = f_peak, f = f_peak;
  for (int k = 0; k < 3000; ++k) {
    f = r.step(depth);
    EXPECT_LE(f, f_prev * (1 + 1e-9)) << "the held force only falls, t = " << r.t;
    f_prev = f;
  }
  // The instantaneous answer at the same depth (a fresh body, one jump) bounds it from above, the
  // instantaneous answer times g(hold + ramp) from below.
  BrainRun fresh = make_run(model);
  const double f_inst = fresh.step(depth);
  EXPECT_LT(f, f_inst);
  EXPECT_GT(f, f_inst * v.relaxation(r.t - t_hold + 0.2) * (1 - 1e-3));
  std::printf("brain: press 4 mm in 0.2 s: %.4f N, after 3 s held %.4f N (instantaneous %.4f N, "
              "g(3.2 s) = %.3f)\n", f_peak, f, f_inst, v.relaxation(3.2));
  // Slide 3 mm along the surface and back, 0.6 s, then release in 0.1 s and wait 1 s.
  const Vec3 side = kUp.cross(Vec3::UnitZ()).normalized();
  for (int k = 0; k <= 300; ++k) r.step(depth, 0.003 * k / 300 * side);
  for (int k = 300; k >= 0; --k) r.step(depth, 0.003 * k / 300 * side);
  for (int k = 100; k >= 0; --k) r.step(depth * k / 100);
  for (int k = 0; k < 1000; ++k) EXPECT_LE(r.step(-0.002), 1e-12);

  // A slower press (2 s) to the same depth needs less force than the 0.2 s one.
  BrainRun slow = make_run(model);
  double f_slow = 0.0;
  for (int k = 0; k <= 2000; ++k) f_slow = slow.step(depth * k / 2000);
  EXPECT_LT(f_slow, f_peak);
  std::printf("brain: press 4 mm in 2 s: %.4f N\n", f_slow);
}

}  // namespace
}  // namespace neurosim::interaction
