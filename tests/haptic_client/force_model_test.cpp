// The pure force model (haptic_client/force_model.hpp) in simulated time: extrapolation order,
// blend step bound, watchdog fade, NaN handling, server loss, passivity limit, clamp.
#include "haptic_client/force_model.hpp"
#include "fake_server.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

namespace nh = neurosim::haptic;
using Eigen::Matrix3d;
using Eigen::Vector3d;

namespace {

constexpr std::int64_t kTick = 1000000;  // 1 ms in ns

// A smooth nonlinear (quadratic) force law standing in for the server: F(x) = c + A d + q(d),
// q_i(d) = 0.5 d^T H_i d, d = x - xr. Its exact Jacobian is what the server sends as K.
struct QuadraticLaw {
  Vector3d xr{0.01, -0.02, 0.0};
  Vector3d c{0.1, -0.05, 1.2};
  Matrix3d a;
  Matrix3d h[3];
  QuadraticLaw() {
    a << -250, 30, 10, 25, -300, -20, 15, -10, -400;
    for (int i = 0; i < 3; ++i) {
      Matrix3d m;
      m << 1.0 + i, 0.3, -0.2, 0.3, 2.0 - 0.5 * i, 0.4, -0.2, 0.4, 3.0;
      h[i] = 4e4 * m;  // symmetric, unit N/m^2
    }
  }
  Vector3d force(const Vector3d& x) const {
    const Vector3d d = x - xr;
    Vector3d f = c + a * d;
    for (int i = 0; i < 3; ++i) f[i] += 0.5 * d.dot(h[i] * d);
    return f;
  }
  Matrix3d jacobian(const Vector3d& x) const {
    const Vector3d d = x - xr;
    Matrix3d j = a;
    for (int i = 0; i < 3; ++i) j.row(i) += (h[i] * d).transpose();
    return j;
  }
};

nh::ForceModelConfig open_config() {
  nh::ForceModelConfig c;
  c.ramp_in_s = 0;
  c.blend_s = 0;
  c.max_force_step_n = 100;
  c.max_stiffness_n_per_m = 1e5;  // do not touch the law's stiffness
  c.max_damping_n_s_per_m = 1e3;
  return c;
}

nh::ForceInput input(std::int64_t t_ns, const Vector3d& x,
                     const nh::ContactModelData* m = nullptr) {
  nh::ForceInput in;
  in.now_ns = t_ns;
  in.position_m = x;
  in.new_model = m;
  return in;
}

}  // namespace

TEST(haptic_force_model, ExtrapolationErrorShrinksQuadraticallyWithStep) {
  const QuadraticLaw law;
  const Vector3d x0(0.012, -0.019, -0.001);
  nh::ContactModelData m;
  m.x0_m = x0;
  m.f0_n = law.force(x0);
  m.k_n_per_m = law.jacobian(x0);
  m.normal = Vector3d::UnitZ();
  m.in_contact = true;
  m.validity_radius_m = 0.01;
  const Vector3d dir = Vector3d(0.3, -0.5, 0.8).normalized();
  std::vector<double> err;
  for (double step : {2e-3, 1e-3, 5e-4, 2.5e-4}) {
    nh::ForceModel fm(open_config());
    const Vector3d x = x0 + step * dir;
    const nh::ForceOutput out = fm.step(input(0, x, &m));
    ASSERT_TRUE(out.in_contact);
    const double e = (out.force_n - law.force(x)).norm();
    ASSERT_GT(e, 0) << "a quadratic law cannot be matched exactly by a linear model";
    err.push_back(e);
  }
  for (std::size_t i = 1; i < err.size(); ++i) {
    const double ratio = err[i - 1] / err[i];
    EXPECT_NEAR(ratio, 4.0, 0.2) << "halving the step must quarter the error (second order)";
  }
  // And it is the law's second-order term, 0.5 h^2 u^T H_i u, nothing else.
  Vector3d q;
  for (int i = 0; i < 3; ++i) q[i] = 0.5 * dir.dot(law.h[i] * dir);
  EXPECT_NEAR(err.back(), 2.5e-4 * 2.5e-4 * q.norm(), 1e-9);
}

TEST(haptic_force_model, UnilateralAndValidityRadius) {
  const nh::testing::HalfSpace tissue;
  const nh::ContactModelData m = tissue.model_at(Vector3d(0, 0, -0.002), 1, 0);
  // Above the surface the linear law would pull the tool in: zero instead.
  EXPECT_EQ(nh::ForceModel::extrapolate(m, Vector3d(0, 0, 0.001)), Vector3d::Zero());
  EXPECT_NEAR(nh::ForceModel::extrapolate(m, Vector3d(0, 0, -0.003)).z(), 700 * 0.003, 1e-12);
  // Beyond the validity radius (10 mm) the displacement is limited to it.
  const Vector3d far = nh::ForceModel::extrapolate(m, Vector3d(0, 0, -0.05));
  EXPECT_NEAR(far.z(), 700 * (0.002 + 0.01), 1e-12);
}

TEST(haptic_force_model, ModelTimeoutFadesForceWithinTwentyMilliseconds) {
  nh::ForceModelConfig c;  // defaults: 50 ms timeout, 20 ms fade, 0.5 s ramp-in
  nh::ForceModel fm(c);
  const nh::testing::HalfSpace tissue;
  const Vector3d x(0, 0, -0.002);
  std::int64_t t = 0;
  nh::ForceOutput out;
  for (int k = 0; k < 1000; ++k, t += kTick) {
    const nh::ContactModelData m = tissue.model_at(x, static_cast<std::uint64_t>(k + 1), t);
    out = fm.step(input(t, x, &m));
  }
  const double f_steady = out.force_n.norm();
  ASSERT_NEAR(f_steady, 1.4, 1e-9);
  const std::int64_t last_model_t = t - kTick;
  double previous = f_steady;
  double max_step = 0;
  for (; t <= last_model_t + 100 * kTick; t += kTick) {
    out = fm.step(input(t, x));
    const double f = out.force_n.norm();
    const double age_ms = 1e-6 * static_cast<double>(t - last_model_t);
    max_step = std::max(max_step, std::abs(f - previous));
    EXPECT_LE(f, previous + 1e-12) << "force must not grow while the model is stale";
    if (age_ms <= 50.0 + 1e-9) {
      EXPECT_NEAR(f, f_steady, 1e-9) << "age " << age_ms << " ms";
    }
    if (age_ms >= 70.0 - 1e-9) {
      EXPECT_EQ(f, 0.0) << "age " << age_ms << " ms: must be zero by 50 + 20 ms";
    }
    previous = f;
  }
  EXPECT_LE(max_step, c.max_force_step_n + 1e-12);
  EXPECT_EQ(fm.counters().timeouts, 1u);
}

TEST(haptic_force_model, NewModelIsBlendedWithBoundedSteps) {
  nh::ForceModelConfig c;
  c.ramp_in_s = 0;
  nh::ForceModel fm(c);
  nh::testing::HalfSpace soft;
  soft.k_n_per_m = 200;
  nh::testing::HalfSpace stiff;  // 700 N/m
  const Vector3d x(0, 0, -0.003);
  std::int64_t t = 0;
  for (int k = 0; k < 10; ++k, t += kTick) {
    const auto m = soft.model_at(x, 1, t);
    fm.step(input(t, x, &m));
  }
  double prev = 0.6;
  double max_step = 0;
  nh::ForceOutput out;
  for (int k = 0; k < 20; ++k, t += kTick) {
    const auto m = stiff.model_at(x, 2, t);  // jump from 0.6 N to 2.1 N
    out = fm.step(input(t, x, &m));
    max_step = std::max(max_step, std::abs(out.force_n.z() - prev));
    prev = out.force_n.z();
  }
  EXPECT_NEAR(out.force_n.z(), 2.1, 1e-9);
  // 1.5 N over a 5 ms blend: 0.3 N per tick, limited to the 0.25 N bound.
  EXPECT_LE(max_step, c.max_force_step_n + 1e-12);
  EXPECT_GT(max_step, 0.1);
}

TEST(haptic_force_model, RampInAtStartHasNoKick) {
  nh::ForceModelConfig c;  // 0.5 s ramp-in
  nh::ForceModel fm(c);
  const nh::testing::HalfSpace tissue;
  const Vector3d x(0, 0, -0.004);  // starts deep in the tissue: 2.8 N
  double prev = 0, max_step = 0;
  std::int64_t t = 0;
  for (int k = 0; k < 700; ++k, t += kTick) {
    const auto m = tissue.model_at(x, static_cast<std::uint64_t>(k + 1), t);
    const double f = fm.step(input(t, x, &m)).force_n.norm();
    max_step = std::max(max_step, std::abs(f - prev));
    prev = f;
  }
  EXPECT_NEAR(prev, 2.8, 1e-9);
  EXPECT_LE(max_step, 2.8 * 1e-3 / 0.5 + 1e-9);  // linear ramp over 0.5 s
}

TEST(haptic_force_model, NaNGivesZeroForceAndIsCounted) {
  nh::ForceModelConfig c;
  c.ramp_in_s = 0.01;
  nh::ForceModel fm(c);
  const nh::testing::HalfSpace tissue;
  const Vector3d x(0, 0, -0.002);
  std::int64_t t = 0;
  for (int k = 0; k < 100; ++k, t += kTick) {
    const auto m = tissue.model_at(x, 1, t);
    fm.step(input(t, x, &m));
  }
  // A model with NaN is refused; the previous model stays in use.
  auto bad = tissue.model_at(x, 2, t);
  bad.k_n_per_m(1, 2) = std::numeric_limits<double>::quiet_NaN();
  auto out = fm.step(input(t, x, &bad));
  EXPECT_EQ(fm.counters().nan_models, 1u);
  EXPECT_NEAR(out.force_n.z(), 1.4, 1e-9);
  EXPECT_EQ(out.model_sequence, 1u);
  t += kTick;
  // NaN position (or velocity): zero force at once, counted.
  out = fm.step(input(t, Vector3d(0, std::numeric_limits<double>::quiet_NaN(), -0.002)));
  EXPECT_EQ(out.force_n, Vector3d::Zero());
  EXPECT_EQ(fm.counters().nan_inputs, 1u);
  t += kTick;
  auto in = input(t, x);
  in.velocity_m_per_s.x() = std::numeric_limits<double>::infinity();
  EXPECT_EQ(fm.step(in).force_n, Vector3d::Zero());
  EXPECT_EQ(fm.counters().nan_inputs, 2u);
  // Back to sane input: the force ramps in again (no kick) and returns to the law.
  double prev = 0, max_step = 0;
  for (int k = 0; k < 30; ++k) {
    t += kTick;
    const auto m = tissue.model_at(x, 3, t);
    out = fm.step(input(t, x, &m));
    EXPECT_TRUE(out.force_n.allFinite());
    max_step = std::max(max_step, std::abs(out.force_n.z() - prev));
    prev = out.force_n.z();
  }
  EXPECT_NEAR(prev, 1.4, 1e-9);
  EXPECT_LE(max_step, c.max_force_step_n + 1e-12);
}

TEST(haptic_force_model, ServerGoneFadesForceAndReconnectRampsIn) {
  nh::ForceModelConfig c;
  c.ramp_in_s = 0.05;
  nh::ForceModel fm(c);
  const nh::testing::HalfSpace tissue;
  const Vector3d x(0, 0, -0.002);
  std::int64_t t = 0;
  for (int k = 0; k < 100; ++k, t += kTick) {
    const auto m = tissue.model_at(x, 1, t);
    fm.step(input(t, x, &m));
  }
  // Liveliness says the server is gone while its last model is still fresh: fade within 20 ms
  // (not after the 50 ms timeout), steps bounded, even if stray models still arrive.
  double prev = 1.4;
  for (int k = 1; k <= 25; ++k, t += kTick) {
    const auto m = tissue.model_at(x, 2, t);
    auto in = input(t, x, &m);
    in.server_alive = false;
    const double f = fm.step(in).force_n.norm();
    EXPECT_LE(std::abs(f - prev), c.max_force_step_n + 1e-12);
    EXPECT_LE(f, prev + 1e-12);
    if (k >= 20) {
      EXPECT_EQ(f, 0.0) << k << " ms after the server was lost";
    }
    prev = f;
  }
  EXPECT_EQ(fm.counters().server_lost, 1u);
  // Back: the first models ramp in from zero.
  const auto m = tissue.model_at(x, 5, t);
  const auto out = fm.step(input(t, x, &m));
  EXPECT_GT(out.force_n.z(), 0);
  EXPECT_LT(out.force_n.z(), 0.1);
}

TEST(haptic_force_model, StiffnessIsLimitedToThePassiveBoundAndForceClamped) {
  nh::ForceModelConfig c;  // Omni: 700 N/m, 5 N s/m, T = 1 ms, margin 2
  c.ramp_in_s = 0;
  c.max_force_step_n = 100;
  nh::ForceModel fm(c);
  // Passivity: K < 2 b / T with margin 2 → b = 0.7 N s/m for 700 N/m.
  EXPECT_NEAR(fm.damping(), 0.7, 1e-12);
  EXPECT_LE(fm.scene_stiffness_limit(), 2 * fm.damping() / c.period_s / c.passivity_margin + 1e-9);
  nh::testing::HalfSpace hard;
  hard.k_n_per_m = 5000;
  const Vector3d x0(0, 0, 0);  // at the surface: f0 = 0
  const auto m = hard.model_at(Vector3d(0, 0, -1e-12), 1, 0);
  const auto out = fm.step(input(0, Vector3d(0, 0, -0.001), &m));
  EXPECT_EQ(fm.counters().stiffness_limited, 1u);
  EXPECT_NEAR(out.force_n.z(), 0.7, 1e-6);  // 700 N/m x 1 mm, not 5 N
  // Deep: clamped to the device maximum.
  nh::ForceModel fm2(c);
  const auto m2 = nh::testing::HalfSpace{}.model_at(Vector3d(0, 0, -0.01), 1, 0);
  EXPECT_NEAR(fm2.step(input(0, Vector3d(0, 0, -0.01), &m2)).force_n.norm(), 3.3, 1e-12);
  (void)x0;
}

TEST(haptic_force_model, ConfigIsChecked) {
  nh::ForceModelConfig c;
  c.max_force_n = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(nh::ForceModel{c}, std::invalid_argument);
  c = {};
  c.period_s = 0;
  EXPECT_THROW(nh::ForceModel{c}, std::invalid_argument);
}

TEST(haptic_force_model, ClampedForceStillFadesWithinTwentyMilliseconds) {
  // A stiff tissue pushing far beyond the device maximum: the fade must scale the clamped
  // force (else it would sit at the clamp until the gain is tiny, then drop late).
  nh::ForceModelConfig c;
  nh::ForceModel fm(c);
  nh::testing::HalfSpace tissue;
  tissue.k_n_per_m = 700;
  const Vector3d x(0, 0, -0.05);  // 35 N unclamped
  std::int64_t t = 0;
  for (int k = 0; k < 1000; ++k, t += kTick) {
    const auto m = tissue.model_at(x, static_cast<std::uint64_t>(k + 1), t);
    fm.step(input(t, x, &m));
  }
  const std::int64_t last = t - kTick;
  for (; t <= last + 80 * kTick; t += kTick) {
    const double f = fm.step(input(t, x)).force_n.norm();
    if (t - last >= 70 * kTick) {
      EXPECT_EQ(f, 0.0) << 1e-6 * static_cast<double>(t - last) << " ms";
    }
    if (t - last == 60 * kTick) {
      EXPECT_NEAR(f, 3.3 * 0.5, 1e-9) << "half way through the fade";
    }
  }
}

TEST(haptic_force_model, SceneFactorsScaleForceAndTheStiffnessLimit) {
  // Scene haptics: device force = force_scale * F, scene displacement = workspace_scale * device
  // displacement; the device-side limit (700 N/m) becomes 700 / (fs * ws) in the scene.
  nh::ForceModelConfig c;
  c.force_scale = 0.1;
  c.workspace_scale = 0.5;
  c.ramp_in_s = 0;
  c.max_force_step_n = 100;
  nh::ForceModel fm(c);
  EXPECT_NEAR(fm.scene_stiffness_limit(), 700 / (0.1 * 0.5), 1e-9);
  nh::testing::HalfSpace tissue;
  tissue.k_n_per_m = 5000;  // below the scene limit of 14000 N/m: not scaled
  const auto m = tissue.model_at(Vector3d(0, 0, -0.002), 1, 0);
  const auto out = fm.step(input(0, Vector3d(0, 0, -0.003), &m));
  EXPECT_EQ(fm.counters().stiffness_limited, 0u);
  EXPECT_NEAR(out.force_n.z(), 0.1 * 5000 * 0.003, 1e-12);
}

// Viscoelastic tissue: held at x0, the rendered force is f0 relaxed by the model's parts over
// its age (ContactModel.relaxing_forces), K dx on top; a part with tau <= 0 or NaN rejects the
// model; the passivity limit scales the parts with f0 and K.
TEST(haptic_force_model, RelaxingPartsRelaxTheHeldForce) {
  nh::ForceModelConfig c = open_config();
  c.damping_n_s_per_m = 0;
  c.enforce_passivity = false;  // K as sent (the limit below)
  nh::ForceModel fm(c);
  nh::ContactModelData m;
  m.tool_sequence = 1;
  m.reference_time_ns = 0;
  m.in_contact = true;
  m.normal = Vector3d::UnitZ();
  m.f0_n = Vector3d(0, 0, 1.0);
  m.k_n_per_m = -300 * Matrix3d::Identity();
  m.validity_radius_m = 0.01;
  m.relaxing[0] = {Vector3d(0, 0, 0.4), 0.01};
  m.relaxing[1] = {Vector3d(0, 0, 0.2), 0.5};
  m.num_relaxing = 2;
  const Vector3d x = m.x0_m + Vector3d(0, 0, -0.001);  // 1 mm in: K dx = +0.3 N
  for (int k = 0; k <= 40; ++k) {
    const double s = 1e-3 * k;
    const auto out = fm.step(input(k * kTick, x, k == 0 ? &m : nullptr));
    const double expected = 1.0 + 0.3 + 0.4 * (std::exp(-s / 0.01) - 1) + 0.2 * (std::exp(-s / 0.5) - 1);
    EXPECT_NEAR(out.force_n.z(), expected, 1e-12) << "age " << s << " s";
  }
  // Bad parts: the model is rejected (counted), the previous one stays in use.
  nh::ContactModelData bad = m;
  bad.tool_sequence = 2;
  bad.relaxing[1].tau_s = 0;
  fm.step(input(41 * kTick, x, &bad));
  bad.relaxing[1].tau_s = std::numeric_limits<double>::quiet_NaN();
  fm.step(input(42 * kTick, x, &bad));
  EXPECT_EQ(fm.counters().nan_models, 2u);
  EXPECT_EQ(fm.step(input(43 * kTick, x)).model_sequence, 1u);

  // Scaled to the passive limit: f0, K and the parts alike (the held force keeps its shape).
  nh::ForceModelConfig lim = open_config();
  lim.max_stiffness_n_per_m = 150;
  lim.enforce_passivity = false;
  lim.damping_n_s_per_m = 0;
  nh::ForceModel fl(lim);
  const double sc = 150.0 / 300.0;
  for (int k = 0; k <= 20; ++k) {
    const double s = 1e-3 * k;
    const auto out = fl.step(input(k * kTick, m.x0_m, k == 0 ? &m : nullptr));
    const double expected = sc * (1.0 + 0.4 * (std::exp(-s / 0.01) - 1) + 0.2 * (std::exp(-s / 0.5) - 1));
    EXPECT_NEAR(out.force_n.z(), expected, 1e-12) << "age " << s << " s";
  }
}
