// Replay of a viscoelastic body (server/cli/replay.hpp with a relaxing material): time enters the
// step, and the replay steps at the recording's sample times. Two replays give bit-identical
// forces; they equal a Simulation stepped in process at the same sample times (what the live
// server does with the stations' source times); the same poses at other times give other forces
// (the held press relaxes by the kernel's amount over the recording's time, not the step count);
// a step at the time of the last one replaces it.
#include "server/cli/replay.hpp"
#include "server/scene/compile.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim {
namespace {

namespace ni = interaction;

scene::Model block_model() {
  std::ostringstream o;
  o << "name: \"visco_replay\"\n"
    << "meshes { id: \"block\" generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 "
       "z: 0.02 } } cell_size_m: 0.004 seed: 1 }\n"
    << "  material { name: \"tissue\" youngs_modulus_pa: 3000 poisson_ratio: 0.45\n"
    << "    viscoelastic { terms { g: 0.3 tau_s: 0.05 } terms { g: 0.2 tau_s: 0.5 } } }\n"
    << "  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-6 } } } }\n"
    << "tools { id: \"probe\" tip_radius_m: 0.003 shaft_radius_m: 0.001 shaft_length_m: 0.05 "
       "max_speed_m_per_s: 2 }\n"
    << "effects { tier: LINEAR coupling: false tool_contact: true deformation_output: true }\n";
  return scene::compile(scene::parse_scene(o.str(), "visco_replay.scene"), "visco_replay.scene");
}

// A press into the top face (1 mm in 0.1 s) held for 0.4 s; sample k at time_scale * k ms,
// with a fixed jitter of up to 0.3 ms (sample times need not be regular).
replay::Station press_station(double time_scale) {
  replay::Station s;
  s.file = "press.rec";
  s.id = "s1";
  for (int k = 0; k <= 500; ++k) {
    recording::Sample r;
    const double jitter = 3e-4 * ((k * 7919) % 11) / 10.0;
    r.set_time_s(time_scale * (1e-3 * k + (k > 0 && k < 500 ? jitter : 0.0)));
    const double depth = 0.001 * std::min(1.0, k / 100.0);
    r.mutable_position_m()->set_x(0.0101);
    r.mutable_position_m()->set_y(0.0098);
    r.mutable_position_m()->set_z(0.02 + 0.003 - depth);
    r.mutable_orientation()->set_w(1.0);
    r.set_tool_sequence(static_cast<std::uint64_t>(k + 1));
    s.samples.push_back(r);
  }
  return s;
}

struct Trace {
  std::vector<double> time_s, force_z;
};

Trace replay_once(const scene::Model& model, double time_scale) {
  auto sim = ni::Simulation::build(model);
  Trace t;
  replay::run(*sim, {press_station(time_scale)}, [&](const replay::StepView& v) {
    t.time_s.push_back(v.time_s);
    t.force_z.push_back((*v.contacts)[0].force_n.z());
  });
  return t;
}

TEST(replay_viscoelastic, DeterministicAtTheSampleTimesAndEqualToTheInProcessSteps) {
  const scene::Model model = block_model();
  const Trace a = replay_once(model, 1.0), b = replay_once(model, 1.0);
  ASSERT_EQ(a.force_z.size(), 501u);
  EXPECT_EQ(a.force_z, b.force_z);  // bit-identical
  // In process at the sample times (what the live server does with the source times).
  auto sim = ni::Simulation::build(model);
  const replay::Station s = press_station(1.0);
  std::vector<ni::ToolContact> c;
  ni::StepStats st;
  for (std::size_t k = 0; k < s.samples.size(); ++k) {
    sim->step_at(s.samples[k].time_s(), {replay::pose_of(s.samples[k], 0)}, c, st);
    EXPECT_EQ(c[0].force_n.z(), a.force_z[k]) << "sample " << k;
  }
  // The held press relaxes: the force at the end is below the one at the end of the ramp.
  EXPECT_LT(a.force_z.back(), 0.8 * a.force_z[100]);
  // The same poses twice as far apart in time relax further (time enters, not the step count).
  const Trace slow = replay_once(model, 2.0);
  EXPECT_LT(slow.force_z.back(), a.force_z.back() * (1.0 - 1e-3));
  std::printf("held press: end of ramp %.5f N, after 0.4 s %.5f N, after 0.8 s %.5f N\n",
              a.force_z[100], a.force_z.back(), slow.force_z.back());
}

// A step at the time of the last one replaces it (the live server repeats a pose at its time on a
// deadline while it waits for the next sample): every pose stepped twice at its time gives, bit
// for bit, the forces of stepping it once; and a newer pose at the same time gives what that pose
// alone at that time gives.
TEST(replay_viscoelastic, AStepAtTheSameTimeReplacesTheLastOne) {
  const scene::Model model = block_model();
  const replay::Station s = press_station(1.0);
  auto once = ni::Simulation::build(model), twice = ni::Simulation::build(model),
       replaced = ni::Simulation::build(model);
  std::vector<ni::ToolContact> a, b, c;
  ni::StepStats st;
  int in_contact = 0;
  for (std::size_t k = 0; k < s.samples.size(); ++k) {
    const double t = s.samples[k].time_s();
    const ni::ToolPose p = replay::pose_of(s.samples[k], 0);
    once->step_at(t, {p}, a, st);
    twice->step_at(t, {p}, b, st);
    twice->step_at(t, {p}, b, st);
    // First a pose 0.2 mm off, then the sample's pose at the same time.
    ni::ToolPose off = p;
    off.tip_m.z() -= 2e-4;
    replaced->step_at(t, {off}, c, st);
    replaced->step_at(t, {p}, c, st);
    ASSERT_EQ(a[0].in_contact, b[0].in_contact) << "sample " << k;
    in_contact += a[0].in_contact;
    EXPECT_EQ(a[0].force_n, b[0].force_n) << "sample " << k;
    EXPECT_EQ(a[0].force_n, c[0].force_n) << "sample " << k;
    EXPECT_EQ(a[0].num_relaxing, b[0].num_relaxing);
    for (int j = 0; j < a[0].num_relaxing; ++j)
      EXPECT_EQ(a[0].relaxing[j].force_n, b[0].relaxing[j].force_n) << "sample " << k;
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GT(in_contact, 400);
}

}  // namespace
}  // namespace neurosim
