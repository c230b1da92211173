// The haptic loop against rigid constraint planes (a skull) in simulated time: a tool driven
// into a plane stays outside, a simulated hand pressing on it comes to rest without gaining
// energy (and a negative control without the passivity limit does not), a corner holds the
// proxy in the free wedge and lets it slide along the edge, a diagonal push slides along the
// plane, and the wall fades with bounded steps when the planes vanish or the model times out.
#include "fake_server.hpp"
#include "haptic_client/loop.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>

namespace nh = neurosim::haptic;
using Eigen::Vector3d;

namespace {

constexpr double kT = 1e-3;            // loop period, unit s
constexpr double kRampDone_s = 0.6;    // ramp-in (0.5 s) is over
constexpr double kProxyTol_m = 1e-10;  // the proxy is never further behind a plane (solve tol)

// Piecewise-linear motion: p0 until t0, then velocity v1 for d1 seconds, then v2 for d2
// seconds, then holds.
class LinearScript : public nh::Script {
 public:
  LinearScript(const Vector3d& p0, double t0, const Vector3d& v1, double d1,
               const Vector3d& v2 = Vector3d::Zero(), double d2 = 0)
      : p0_(p0), t0_(t0), v1_(v1), d1_(d1), v2_(v2), d2_(d2) {}
  std::string name() const override { return "linear"; }
  Vector3d position(double t) const override {
    const double a = std::clamp(t - t0_, 0.0, d1_);
    const double b = std::clamp(t - t0_ - d1_, 0.0, d2_);
    return p0_ + a * v1_ + b * v2_;
  }

 private:
  Vector3d p0_;
  double t0_;
  Vector3d v1_;
  double d1_;
  Vector3d v2_;
  double d2_;
};

nh::RigidPlane plane(const Vector3d& p, const Vector3d& n) {
  nh::RigidPlane r;
  r.point_m = p;
  r.normal = n.normalized();
  return r;
}

// A fake server with no tissue near (only the rigid planes act).
nh::testing::FakeLink skull_link(std::initializer_list<nh::RigidPlane> planes) {
  nh::testing::FakeLink link;
  link.tissue.surface_z_m = -10;
  for (const auto& p : planes) EXPECT_TRUE(link.planes.add(p));
  return link;
}

nh::LoopConfig loop_config(std::size_t ticks) {
  nh::LoopConfig cfg;
  cfg.trace_capacity = ticks;
  return cfg;
}

// Every tick: |F| within the clamp, the step within its bound.
void expect_force_limits(const nh::HapticLoop& loop) {
  const auto& c = loop.force_model().config();
  Vector3d prev = Vector3d::Zero();
  for (const auto& t : loop.trace()) {
    ASSERT_LE(t.force_n.norm(), c.max_force_n + 1e-12) << "t " << t.t_s;
    ASSERT_LE((t.force_n - prev).norm(), c.max_force_step_n + 1e-12) << "t " << t.t_s;
    prev = t.force_n;
  }
}

}  // namespace

TEST(haptic_loop_rigid, ToolDrivenIntoPlaneAtHalfMeterPerSecondStaysOutside) {
  // Plane z >= 0; the scripted tool goes from z = +5 mm to -3 mm at 0.5 m/s (16 ms), then holds.
  const double v = 0.5, depth = 0.003;
  nh::ScriptDevice dev(std::make_unique<LinearScript>(Vector3d(0.01, 0.02, 0.005), kRampDone_s,
                                                      Vector3d(0, 0, -v), 0.008 / v));
  auto link = skull_link({plane(Vector3d::Zero(), Vector3d::UnitZ())});
  const std::size_t ticks = 900;
  nh::HapticLoop loop(loop_config(ticks), dev, &link, nullptr);
  loop.run_simulated(ticks);
  const nh::ForceModel& fm = loop.force_model();
  const double k = fm.wall_stiffness_scene(), b = fm.damping();
  ASSERT_EQ(k, 700);
  expect_force_limits(loop);
  double worst_lag_m = 0;
  int contact = 0;
  for (const auto& t : loop.trace()) {
    // The proxy never crosses the plane.
    ASSERT_GE(t.proxy_m.z(), -kProxyTol_m) << "t " << t.t_s;
    const double pen = std::max(0.0, -t.position_m.z());
    if (pen <= kProxyTol_m) continue;  // (the crossing tick may land on the plane itself)
    EXPECT_TRUE(t.rigid_contact) << "t " << t.t_s;
    ++contact;
    // The force holds the device out: the wall pushes along +z only, never more than the
    // spring plus the passivity damper.
    EXPECT_NEAR(t.force_n.x(), 0, 1e-12);
    EXPECT_NEAR(t.force_n.y(), 0, 1e-12);
    EXPECT_LE(t.force_n.z(), k * pen + b * v + 1e-9) << "t " << t.t_s;
    worst_lag_m = std::max(worst_lag_m, pen - t.force_n.z() / k);
  }
  EXPECT_GT(contact, 250);
  // Penetration bounded by force / stiffness: during the 16 ms impact within what the step bound
  // lets the force lag (k v T = 0.35 N per tick against 0.25 N: <= 1.5 mm), at rest exactly.
  EXPECT_LT(worst_lag_m, 1.5e-3);
  const auto& last = loop.trace().back();
  EXPECT_NEAR(-last.position_m.z(), depth, 1e-12);
  EXPECT_NEAR(last.force_n.z(), k * depth, 1e-9);  // 2.1 N: penetration = F / k
  EXPECT_NEAR(last.proxy_m.z(), 0, kProxyTol_m);
  // Its tangential position follows the device.
  EXPECT_NEAR(last.proxy_m.x(), 0.01, 1e-15);
  EXPECT_NEAR(last.proxy_m.y(), 0.02, 1e-15);
  const nh::ForceTraceSummary s = loop.force_trace();
  EXPECT_EQ(s.rigid_contact_ticks, static_cast<std::uint64_t>(contact));
  EXPECT_NEAR(s.max_wall_penetration_m, depth, 1e-12);
  EXPECT_GT(s.max_wall_force_n, k * depth);  // the damper adds while the tool moves in
  EXPECT_LE(s.max_wall_force_n, k * depth + b * v + 1e-9);
}

namespace {

struct HandWallRun {
  std::vector<double> max_energy_per_second;
  double velocity_rms_last_second = 0;
  double min_proxy_z = 0;
  double max_force = 0;
  std::uint64_t rigid_ticks = 0;
};

// The simulated hand pulled 4 mm into the plane z >= 0 for 10 s. Energy (kinetic + grip spring
// + wall spring) relative to the static equilibrium, max per simulated second.
HandWallRun run_hand_on_wall(const nh::ForceModelConfig& force, const nh::HandParams& hand) {
  const double target_z = -0.004;
  nh::HandDevice dev(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, target_z)), hand);
  dev.set_state(Vector3d(0, 0, 0.002), Vector3d::Zero());
  auto link = skull_link({plane(Vector3d::Zero(), Vector3d::UnitZ())});
  nh::LoopConfig cfg;
  cfg.force = force;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  const double k_wall = loop.force_model().wall_stiffness_scene();
  const double kg = hand.stiffness_n_per_m;
  const double z_eq = kg * target_z / (kg + k_wall);
  auto potential = [&](const Vector3d& p) {
    const double pen = std::max(0.0, -p.z());
    return 0.5 * kg * (Vector3d(0, 0, target_z) - p).squaredNorm() + 0.5 * k_wall * pen * pen;
  };
  HandWallRun r;
  double v2 = 0;
  for (int s = 0; s < 10; ++s) {
    double emax = 0;
    for (int i = 0; i < 1000; ++i) {
      const std::int64_t tick = s * 1000 + i;
      loop.tick(tick * 1000000, kT * static_cast<double>(tick), kT, 0);
      const double e = 0.5 * hand.mass_kg * dev.velocity().squaredNorm() +
                       potential(dev.position()) - potential(Vector3d(0, 0, z_eq));
      emax = std::max(emax, e);
      if (s == 9) v2 += dev.velocity().squaredNorm();
      r.max_force = std::max(r.max_force, loop.last_force().norm());
    }
    r.max_energy_per_second.push_back(emax);
  }
  r.velocity_rms_last_second = std::sqrt(v2 / 1000);
  r.rigid_ticks = loop.force_trace().rigid_contact_ticks;
  return r;
}

}  // namespace

TEST(haptic_loop_rigid, SimulatedHandAgainstPlaneComesToRestWithoutGainingEnergy) {
  nh::ForceModelConfig force;  // Omni: wall 700 N/m = the passive limit, b = 0.7 N s/m
  nh::HandParams hand;         // 0.15 kg, grip 300 N/m, 3 N s/m
  const HandWallRun r = run_hand_on_wall(force, hand);
  for (std::size_t s = 2; s < r.max_energy_per_second.size(); ++s)
    EXPECT_LE(r.max_energy_per_second[s], r.max_energy_per_second[s - 1] * 1.001 + 1e-12)
        << "second " << s;
  EXPECT_LT(r.max_energy_per_second.back(), 1e-3 * r.max_energy_per_second[1] + 1e-9);
  EXPECT_LT(r.velocity_rms_last_second, 1e-4);  // m/s: no oscillation left
  EXPECT_LE(r.max_force, force.max_force_n + 1e-12);
  EXPECT_GT(r.rigid_ticks, 8000u);  // it really pressed on the wall
}

TEST(haptic_loop_rigid, WallWithoutPassivityLimitDoesOscillate) {
  // Negative control (the test above can fail): a wall far above 2b/T, no damping, no limits.
  nh::ForceModelConfig force;
  force.enforce_passivity = false;
  force.max_stiffness_n_per_m = 1e5;
  force.damping_n_s_per_m = 0;
  force.max_force_n = 1e3;
  force.max_force_step_n = 1e3;
  nh::HandParams hand;
  hand.damping_n_s_per_m = 0.5;
  const HandWallRun r = run_hand_on_wall(force, hand);
  EXPECT_GT(r.max_energy_per_second.back(), 0.5 * r.max_energy_per_second[2]);
  EXPECT_GT(r.velocity_rms_last_second, 1e-3);
}

TEST(haptic_loop_rigid, CornerHoldsTheProxyInTheWedgeAndSlidesAlongTheEdge) {
  // Free wedge x >= 0, z >= 0 (edge along y). The tool goes 2 mm behind both planes, then
  // moves 20 mm along the edge.
  nh::ScriptDevice dev(std::make_unique<LinearScript>(Vector3d(0.002, 0, 0.002), kRampDone_s,
                                                      Vector3d(-0.4, 0, -0.4), 0.01,
                                                      Vector3d(0, 0.1, 0), 0.2));
  auto link = skull_link(
      {plane(Vector3d::Zero(), Vector3d::UnitZ()), plane(Vector3d::Zero(), Vector3d::UnitX())});
  const std::size_t ticks = 900;
  nh::HapticLoop loop(loop_config(ticks), dev, &link, nullptr);
  loop.run_simulated(ticks);
  expect_force_limits(loop);
  const double k = loop.force_model().wall_stiffness_scene();
  int on_edge = 0;
  for (const auto& t : loop.trace()) {
    ASSERT_GE(t.proxy_m.x(), -kProxyTol_m) << "t " << t.t_s;
    ASSERT_GE(t.proxy_m.z(), -kProxyTol_m) << "t " << t.t_s;
    if (t.position_m.x() < -kProxyTol_m && t.position_m.z() < -kProxyTol_m) {
      ++on_edge;
      EXPECT_EQ(t.active_planes, 2u);
      EXPECT_NEAR(t.proxy_m.x(), 0, kProxyTol_m);
      EXPECT_NEAR(t.proxy_m.z(), 0, kProxyTol_m);
      EXPECT_NEAR(t.proxy_m.y(), t.position_m.y(), 1e-15);  // slides along the edge
      EXPECT_NEAR(t.force_n.y(), 0, 1e-12);                 // frictionless: no drag
    }
  }
  EXPECT_GT(on_edge, 250);
  const auto& last = loop.trace().back();
  EXPECT_NEAR(last.proxy_m.y(), 0.02, 1e-12);  // slid the whole 20 mm
  EXPECT_NEAR(last.force_n.x(), k * 0.002, 1e-9);
  EXPECT_NEAR(last.force_n.z(), k * 0.002, 1e-9);
}

TEST(haptic_loop_rigid, DiagonalPushSlidesAlongThePlane) {
  // Plane z >= 0; the tool moves diagonally (+x, -z) at 0.05 m/s per axis from 2 mm above to
  // 1 mm below, then 10 mm along +x at 0.05 m/s.
  nh::ScriptDevice dev(std::make_unique<LinearScript>(Vector3d(0, 0, 0.002), kRampDone_s,
                                                      Vector3d(0.05, 0, -0.05), 0.06,
                                                      Vector3d(0.05, 0, 0), 0.2));
  auto link = skull_link({plane(Vector3d::Zero(), Vector3d::UnitZ())});
  const std::size_t ticks = 1000;
  nh::HapticLoop loop(loop_config(ticks), dev, &link, nullptr);
  loop.run_simulated(ticks);
  expect_force_limits(loop);
  double first_x = -1, last_x = -1;
  for (const auto& t : loop.trace()) {
    ASSERT_GE(t.proxy_m.z(), -kProxyTol_m) << "t " << t.t_s;
    if (!t.rigid_contact) continue;
    if (first_x < 0) first_x = t.proxy_m.x();
    last_x = t.proxy_m.x();
    EXPECT_NEAR(t.proxy_m.x(), t.position_m.x(), 1e-15);  // tangential motion followed
    EXPECT_NEAR(t.proxy_m.z(), 0, kProxyTol_m);
    EXPECT_NEAR(t.force_n.x(), 0, 1e-12);  // frictionless
    EXPECT_GT(t.force_n.z(), 0);
  }
  ASSERT_GE(first_x, 0) << "never touched";
  EXPECT_NEAR(first_x, 0.002, 1e-4);
  EXPECT_NEAR(last_x, 0.013, 1e-12);  // 2 mm diagonal + 1 mm more + 10 mm along the plane
}

namespace {

// Tool held 3 mm behind the plane z >= 0; at t_change the fake server either sends models
// without planes or stops answering. Returns the loop for inspection.
struct FadeRun {
  std::vector<nh::TickTrace> trace;
  double force_before = 0;
};

FadeRun run_fade(bool stop_answering, double t_change) {
  nh::ScriptDevice dev(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, -0.003)));
  auto link = skull_link({plane(Vector3d::Zero(), Vector3d::UnitZ())});
  const std::size_t ticks = 1300;
  nh::HapticLoop loop(loop_config(ticks), dev, &link, nullptr);
  FadeRun r;
  for (std::size_t i = 0; i < ticks; ++i) {
    const double t = kT * static_cast<double>(i);
    if (std::abs(t - t_change) < kT / 2) {
      r.force_before = loop.last_force().z();
      if (stop_answering)
        link.answering = false;
      else
        link.send_planes = false;
    }
    loop.tick(static_cast<std::int64_t>(i) * 1000000, t, kT, 0);
  }
  expect_force_limits(loop);
  r.trace = loop.trace();
  return r;
}

}  // namespace

TEST(haptic_loop_rigid, WallFadesWhenThePlanesVanish) {
  const double t_change = 1.0;
  const FadeRun r = run_fade(false, t_change);
  EXPECT_NEAR(r.force_before, 700 * 0.003, 1e-9);
  // Zero within the watchdog limit + fade of the change (here: the blend, 5 ms + 2 ms latency),
  // every step within the bound (expect_force_limits).
  const double limit = t_change + 0.05 + 0.02;
  double zero_at = -1;
  for (const auto& t : r.trace) {
    if (t.t_s >= limit) {
      EXPECT_EQ(t.force_n.norm(), 0) << "t " << t.t_s;
    }
    if (zero_at < 0 && t.t_s > t_change && t.force_n.norm() == 0) zero_at = t.t_s;
  }
  ASSERT_GT(zero_at, t_change);
  EXPECT_LT(zero_at, t_change + 0.02);
  // Not a jump: it took several ticks (blend and step bound).
  EXPECT_GT(zero_at, t_change + 0.004);
}

TEST(haptic_loop_rigid, WallIsKeptWhileTheModelAgesAndFadesOnTimeout) {
  const double t_change = 1.0;
  const FadeRun r = run_fade(true, t_change);
  EXPECT_NEAR(r.force_before, 700 * 0.003, 1e-9);
  for (const auto& t : r.trace) {
    // Rigid planes stay valid while the model is not timed out (age <= 50 ms).
    if (t.t_s > t_change && t.model_age_s <= 0.05) {
      EXPECT_NEAR(t.force_n.z(), 700 * 0.003, 1e-9) << "t " << t.t_s;
      EXPECT_TRUE(t.rigid_contact);
    }
    // Newest model answers the pose of t_change - 1 ms: zero within 50 + 20 ms of it.
    if (t.t_s >= t_change + 0.07) {
      EXPECT_EQ(t.force_n.norm(), 0) << "t " << t.t_s;
    }
  }
}
