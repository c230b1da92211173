// Devices: the simulated hand against the closed-form damped oscillator (first-order
// convergence of its semi-implicit Euler in the substeps, rest exactly at target + F / k), the
// replay device against the samples written to its file (newest sample at or before t, end,
// header), scripts and device specs refused with the accepted forms.
#include "haptic_client/device.hpp"

#include "idl/wire/recording_io.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

namespace fs = std::filesystem;
namespace nh = neurosim::haptic;
using Eigen::Vector3d;

namespace {

// m y'' + c y' + k y = 0 with y = x - (p + F / k), from y0, v0 (underdamped).
Vector3d closed_form(const nh::HandParams& hp, const Vector3d& rest, const Vector3d& y0,
                     const Vector3d& v0, double t) {
  const double sigma = hp.damping_n_s_per_m / (2.0 * hp.mass_kg);
  const double wd = std::sqrt(hp.stiffness_n_per_m / hp.mass_kg - sigma * sigma);
  return rest +
         std::exp(-sigma * t) * (y0 * std::cos(wd * t) + (v0 + sigma * y0) / wd * std::sin(wd * t));
}

// Largest distance from the closed form over 0.3 s read every 1 ms, with `substeps`.
double hand_error(int substeps, double* amplitude = nullptr) {
  nh::HandParams hp;
  hp.substeps = substeps;
  const Vector3d target(0.01, -0.02, 0.005);
  const Vector3d force(0.3, 0.0, -0.6);  // unit N
  const Vector3d x0(0.0, 0.0, 0.02), v0(0.05, 0.1, 0.0);
  nh::HandDevice hand(std::make_unique<nh::ConstantScript>(target), hp);
  hand.set_state(x0, v0);
  hand.command(force);
  const Vector3d rest = target + force / hp.stiffness_n_per_m;
  double err = 0.0;
  for (int i = 0; i <= 300; ++i) {
    const double t = 1e-3 * i;
    const nh::DeviceReading r = hand.read(t);
    err = std::max(err, (r.position_m - closed_form(hp, rest, x0 - rest, v0, t)).norm());
  }
  if (amplitude != nullptr) *amplitude = (x0 - rest).norm();
  return err;
}

TEST(haptic_device, HandFollowsTheDampedOscillatorToFirstOrder) {
  double amplitude = 0.0;
  const double e20 = hand_error(20, &amplitude);
  const double e40 = hand_error(40);
  const double e80 = hand_error(80);
  ASSERT_GT(amplitude, 0.01);
  EXPECT_LE(e80, 1e-3 * amplitude) << e80;
  // Semi-implicit Euler: the error halves with the step.
  EXPECT_NEAR(e20 / e40, 2.0, 0.1) << e20 << " " << e40;
  EXPECT_NEAR(e40 / e80, 2.0, 0.1) << e40 << " " << e80;
}

TEST(haptic_device, HandRestsAtTargetPlusForceOverStiffness) {
  nh::HandParams hp;
  const Vector3d target(0.0, 0.0, -0.001);
  nh::HandDevice hand(std::make_unique<nh::ConstantScript>(target), hp);
  hand.set_state(Vector3d(0.01, 0.0, 0.0), Vector3d::Zero());
  const Vector3d force(0.0, 0.0, 1.5);  // the tissue pushing back, unit N
  hand.command(force);
  nh::DeviceReading r;
  for (int i = 0; i <= 5000; ++i) r = hand.read(1e-3 * i);      // 5 s, decay exp(-50)
  const Vector3d rest = target + force / hp.stiffness_n_per_m;  // 5 mm above the target
  EXPECT_LE((r.position_m - rest).norm(), 1e-9);
  EXPECT_LE(r.velocity_m_per_s.norm(), 1e-8);
  EXPECT_EQ(r.buttons, 0u);  // above z = 0
  EXPECT_EQ(hand.kind(), "simulated_hand:constant");
}

TEST(haptic_device, ReplayGivesTheNewestSampleAtOrBeforeT) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_device_replay");
  const fs::path file = dir / "r.rec";
  {
    neurosim::recording::Header h;
    h.mutable_device()->set_model("test model");
    h.mutable_device()->set_max_force_n(2.5);
    neurosim::wire::RecordingWriter w(file, h);
    for (int i = 0; i < 5; ++i) {
      neurosim::recording::Sample s;
      s.set_time_s(0.01 * i);
      s.mutable_position_m()->set_x(0.001 * i);
      s.mutable_position_m()->set_z(-0.002 * i);
      if (i != 3) {  // sample 3 without orientation: the identity
        s.mutable_orientation()->set_w(0.0);
        s.mutable_orientation()->set_x(1.0);
      }
      s.mutable_velocity_m_per_s()->set_y(0.5 * i);
      s.set_buttons(static_cast<std::uint32_t>(i));
      w.write(s);
    }
    w.close();
  }
  nh::ReplayDevice d(file.string());
  EXPECT_EQ(d.size(), 5u);
  EXPECT_TRUE(d.scene_frame());
  EXPECT_EQ(d.kind(), "replay:" + file.string());
  EXPECT_EQ(d.model(), "test model");
  EXPECT_EQ(d.max_force_n(), 2.5);
  const struct {
    double t;
    int sample;
  } reads[] = {{0.0, 0},         {0.0099, 0}, {0.01, 1}, {0.015, 1},
               {0.03 - 1e-7, 3}, {0.031, 3},  {0.04, 4}, {1.0, 4}};
  for (const auto& q : reads) {
    const nh::DeviceReading r = d.read(q.t);
    EXPECT_EQ(r.buttons, static_cast<std::uint32_t>(q.sample)) << "t " << q.t;
    EXPECT_EQ(r.position_m.x(), 0.001 * q.sample) << "t " << q.t;
    EXPECT_EQ(r.position_m.z(), -0.002 * q.sample) << "t " << q.t;
    EXPECT_EQ(r.velocity_m_per_s.y(), 0.5 * q.sample) << "t " << q.t;
    EXPECT_EQ(r.orientation,
              q.sample == 3 ? Eigen::Vector4d(1, 0, 0, 0) : Eigen::Vector4d(0, 1, 0, 0))
        << "t " << q.t;
  }
  EXPECT_FALSE(d.finished(0.04));
  EXPECT_TRUE(d.finished(0.041));
  fs::remove_all(dir);
}

TEST(haptic_device, EmptyRecordingAndBadSpecsAreRefused) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_device_bad");
  const fs::path empty = dir / "empty.rec";
  {
    neurosim::wire::RecordingWriter w(empty, neurosim::recording::Header{});
    w.close();
  }
  std::string m = neurosim::testing::message_of([&] { nh::ReplayDevice d(empty.string()); });
  EXPECT_NE(m.find(empty.string()), std::string::npos) << m;
  EXPECT_NE(m.find("no samples"), std::string::npos) << m;
  m = neurosim::testing::message_of([] { nh::make_device("joystick"); });
  EXPECT_NE(m.find("expected omni[:NAME], replay:FILE, script:NAME or hand:SCRIPT"),
            std::string::npos)
      << m;
  for (const auto& name : nh::script_names()) {
    EXPECT_NE(m.find(name), std::string::npos) << m;
    EXPECT_EQ(nh::make_device("script:" + name)->kind(), "script:" + name);
  }
  m = neurosim::testing::message_of([] { nh::make_script("wobble"); });
  EXPECT_NE(m.find("unknown script 'wobble'"), std::string::npos) << m;
  EXPECT_THROW(nh::make_device("script:"), std::invalid_argument);
  if (!nh::omni_supported()) {
    m = neurosim::testing::message_of([] { nh::make_device("omni"); });
    EXPECT_NE(m.find("not built in"), std::string::npos) << m;
  }
  fs::remove_all(dir);
}

}  // namespace

// hold:S: the press's descent, S s at 4 mm deep, the withdrawal; a bad hold time is refused.
TEST(haptic_device, HoldScriptHoldsThePressForItsTime) {
  const auto s = nh::make_script("hold:2.5");
  EXPECT_EQ(s->name(), "hold:2.5");
  EXPECT_NEAR(s->position(0).z(), 0.004, 1e-15);
  for (double t : {1.5, 2.0, 3.0, 3.999}) EXPECT_NEAR(s->position(t).z(), -0.004, 1e-15) << t;
  EXPECT_GT(s->position(4.5).z(), -0.004);
  EXPECT_NEAR(s->position(5.5).z(), 0.004, 1e-15);
  EXPECT_NEAR(s->position(100).z(), 0.004, 1e-15);
  EXPECT_NEAR(nh::make_script("hold")->position(11.4).z(), -0.004, 1e-15);  // 10 s by default
  for (const char* bad : {"hold:", "hold:x", "hold:-1", "hold:1e9", "hold:nan"}) {
    const std::string m = neurosim::testing::message_of([&] { nh::make_script(bad); });
    EXPECT_NE(m.find("hold time"), std::string::npos) << bad << ": " << m;
  }
}
