// The haptic loop in simulated time (no DDS, no sleeping): the simulated hand against a stiff
// half-space does not oscillate, recordings replay to the identical ToolState sequence, the
// bundled script recordings replay, the summary JSON has exactly the documented keys.
#include "haptic_client/loop.hpp"
#include "fake_server.hpp"
#include "idl/wire/recording_io.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <sys/wait.h>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <cstdio>
#include <iterator>
#include <thread>

namespace nh = neurosim::haptic;
namespace fs = std::filesystem;
using Eigen::Vector3d;

namespace {

// Energy of the hand + stylus + tissue spring relative to their static equilibrium (>= 0).
struct EnergyProbe {
  nh::HandParams hand;
  double k_wall;
  double target_z;
  double operator()(const nh::HandDevice& d) const {
    const Vector3d x = d.position();
    const Vector3d v = d.velocity();
    const double z_eq = hand.stiffness_n_per_m * target_z / (hand.stiffness_n_per_m + k_wall);
    auto potential = [&](const Vector3d& p) {
      const double pen = std::max(0.0, -p.z());
      return 0.5 * hand.stiffness_n_per_m * (Vector3d(0, 0, target_z) - p).squaredNorm() +
             0.5 * k_wall * pen * pen;
    };
    return 0.5 * hand.mass_kg * v.squaredNorm() + potential(x) - potential(Vector3d(0, 0, z_eq));
  }
};

struct HandRun {
  std::vector<double> max_energy_per_second;  // max over each simulated second
  double velocity_rms_last_second = 0;
};

// 10 s of the hand pressing into a half-space of stiffness k (server answer 2 ticks late).
// k_felt: the stiffness the device renders (the energy's wall term).
HandRun run_hand(const nh::ForceModelConfig& force, nh::HandParams hand, double k_wall,
                 double k_felt = -1) {
  if (k_felt < 0) k_felt = k_wall;
  const double target_z = -0.004;
  auto dev = nh::HandDevice(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, target_z)), hand);
  dev.set_state(Vector3d(0, 0, 0.002), Vector3d::Zero());  // starts 2 mm above the surface
  nh::testing::FakeLink link;
  link.tissue.k_n_per_m = k_wall;
  nh::LoopConfig cfg;
  cfg.force = force;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  const EnergyProbe energy{hand, k_felt, target_z};
  HandRun r;
  double v2 = 0;
  const int ticks_per_s = 1000;
  for (int s = 0; s < 10; ++s) {
    double emax = 0;
    for (int k = 0; k < ticks_per_s; ++k) {
      const std::int64_t tick = static_cast<std::int64_t>(s) * ticks_per_s + k;
      loop.tick(tick * 1000000, 1e-3 * static_cast<double>(tick), 1e-3, 0);
      emax = std::max(emax, energy(dev));
      if (s == 9) v2 += dev.velocity().squaredNorm();
    }
    r.max_energy_per_second.push_back(emax);
  }
  r.velocity_rms_last_second = std::sqrt(v2 / ticks_per_s);
  return r;
}

}  // namespace

TEST(haptic_loop, SimulatedHandAgainstStiffnessDoesNotOscillate) {
  nh::ForceModelConfig force;  // Phantom Omni defaults: 700 N/m limit, passive damping
  nh::HandParams hand;         // 0.15 kg, grip 300 N/m, 3 N s/m
  const HandRun r = run_hand(force, hand, 700);
  // After ramp-in (1st s), the energy above equilibrium never grows from one second to the next.
  for (std::size_t s = 2; s < r.max_energy_per_second.size(); ++s)
    EXPECT_LE(r.max_energy_per_second[s], r.max_energy_per_second[s - 1] * 1.001 + 1e-12)
        << "second " << s;
  EXPECT_LT(r.max_energy_per_second.back(), 1e-3 * r.max_energy_per_second[1] + 1e-9);
  EXPECT_LT(r.velocity_rms_last_second, 1e-4);  // m/s: at rest
}

TEST(haptic_loop, SimulatedHandAgainstStiffTissueIsRenderedAtThePassiveLimit) {
  // Tissue, 15x stiffer than the device may render: the model (f0 and K) is scaled to 700 N/m,
  // so the closed loop behaves as against 700 N/m and settles.
  nh::ForceModelConfig force;
  nh::HandParams hand;
  const HandRun r = run_hand(force, hand, 1e4, 700);
  for (std::size_t s = 2; s < r.max_energy_per_second.size(); ++s)
    EXPECT_LE(r.max_energy_per_second[s], r.max_energy_per_second[s - 1] * 1.001 + 1e-12)
        << "second " << s;
  EXPECT_LT(r.max_energy_per_second.back(), 1e-3 * r.max_energy_per_second[1] + 1e-9);
  EXPECT_LT(r.velocity_rms_last_second, 1e-4);
}

TEST(haptic_loop, UnsafeStiffnessWithoutPassivityLimitDoesOscillate) {
  // Negative control (the test above can fail): K far above 2b/T, no damping, no limits.
  nh::ForceModelConfig force;
  force.enforce_passivity = false;
  force.max_stiffness_n_per_m = 1e5;
  force.damping_n_s_per_m = 0;
  force.max_force_n = 1e3;
  force.max_force_step_n = 1e3;
  nh::HandParams hand;
  hand.damping_n_s_per_m = 0.5;
  const HandRun r = run_hand(force, hand, 2e4);
  // Sustained (limit cycle at the force clamp) instead of decaying as in the test above.
  EXPECT_GT(r.max_energy_per_second.back(), 0.5 * r.max_energy_per_second[2]);
  EXPECT_GT(r.velocity_rms_last_second, 1e-3);
}

// A participant writing ToolStates under this station's id (it claimed the id first): the
// server answers ITS poses, deep in the tissue, with the same sequence numbers this loop uses
// (both count from 1) but its own source times. The loop (1 mm deep itself) must render none of
// that force: no force at all until models answer its own poses, which it then uses.
class SquatterLink : public nh::Link {
 public:
  nh::testing::HalfSpace tissue;
  bool squatter{true};  // false: answer the loop's own poses
  std::uint64_t answered{0};
  void publish(const nh::ToolSample& s) override { last_ = s; }
  bool take_model(nh::ContactModelData& out) override {
    if (last_.sequence_number == 0) return false;
    out = squatter ? tissue.model_at(Vector3d(0, 0, -0.004), last_.sequence_number,
                                     last_.source_time_ns + 250000)
                   : tissue.model_at(last_.position_m, last_.sequence_number, last_.source_time_ns);
    ++answered;
    return true;
  }
  bool server_alive() override { return true; }

 private:
  nh::ToolSample last_;
};

TEST(haptic_loop, ModelsAnsweringAnotherWritersPosesAreNeverRendered) {
  nh::ScriptDevice dev(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, -0.001)));
  SquatterLink link;
  link.tissue.surface_z_m = 0.0;
  nh::LoopConfig cfg;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  for (std::int64_t k = 0; k < 1000; ++k) {
    loop.tick(k * 1000000, 1e-3 * static_cast<double>(k), 1e-3, 0);
    ASSERT_EQ(dev.last_force().norm(), 0.0) << "tick " << k << ": a squatter's model was rendered";
  }
  EXPECT_EQ(loop.force_trace().foreign_models, link.answered);
  EXPECT_EQ(loop.force_trace().models_seen, 0u);
  // The same link answering the loop's own poses (1 mm deep): force comes.
  link.squatter = false;
  for (std::int64_t k = 1000; k < 2000; ++k)
    loop.tick(k * 1000000, 1e-3 * static_cast<double>(k), 1e-3, 0);
  EXPECT_GT(dev.last_force().z(), 0.5) << "the loop's own models must be rendered";
  EXPECT_GT(loop.force_trace().models_seen, 0u);
}

TEST(haptic_loop, ReplayGivesIdenticalToolStateSequence) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_replay");
  const fs::path first = dir / "stroke.rec", second = dir / "replayed.rec";
  nh::LoopConfig cfg;
  cfg.workspace_origin_m = Vector3d(0.1, 0.05, 0.05);
  cfg.workspace_up = Vector3d(1, 0, 0);  // the cube scene's right face
  nh::testing::FakeLink link1, link2;
  link1.tissue.surface_z_m = -1;  // (z is not the normal here: no contact, just the trajectory)
  link2.tissue.surface_z_m = -1;
  {
    nh::ScriptDevice dev(nh::make_script("stroke"));
    nh::Recorder rec(first.string(), nh::session_header(cfg, dev, "st", "probe", "", "", "test", 0),
                     true);
    nh::HapticLoop loop(cfg, dev, &link1, &rec);
    loop.run_simulated(3000, 1000000000);
    rec.close();
    EXPECT_EQ(rec.written(), 3000u);
  }
  {
    nh::ReplayDevice dev(first.string());
    EXPECT_EQ(dev.size(), 3000u);
    nh::Recorder rec(second.string(),
                     nh::session_header(cfg, dev, "st", "probe", "", "", "replay", 0), true);
    nh::HapticLoop loop(cfg, dev, &link2, &rec);
    loop.run_simulated(5000, 1000000000);  // stops by itself at the end of the recording
    rec.close();
  }
  ASSERT_EQ(link1.published.size(), 3000u);
  ASSERT_EQ(link2.published.size(), link1.published.size());
  for (std::size_t i = 0; i < link1.published.size(); ++i) {
    const auto& a = link1.published[i];
    const auto& b = link2.published[i];
    ASSERT_EQ(a.sequence_number, b.sequence_number);
    ASSERT_EQ(a.source_time_ns, b.source_time_ns);
    ASSERT_EQ(a.position_m, b.position_m) << "tick " << i;
    ASSERT_EQ(a.orientation, b.orientation) << "tick " << i;
    ASSERT_EQ(a.velocity_m_per_s, b.velocity_m_per_s) << "tick " << i;
    ASSERT_EQ(a.buttons, b.buttons) << "tick " << i;
  }
  // The stroke really moved (a constant trajectory would pass trivially).
  EXPECT_GT((link1.published.front().position_m - link1.published.back().position_m).norm(), 1e-3);
  const auto r1 = neurosim::wire::read_recording(first);
  const auto r2 = neurosim::wire::read_recording(second);
  EXPECT_EQ(r1.header.device().kind(), "script:stroke");
  EXPECT_EQ(r2.header.device().kind(), "replay:" + first.string());
  ASSERT_EQ(r1.samples.size(), r2.samples.size());
  for (std::size_t i = 0; i < r1.samples.size(); ++i)
    ASSERT_EQ(r1.samples[i].position_m().SerializeAsString(),
              r2.samples[i].position_m().SerializeAsString());
  fs::remove_all(dir);
}

TEST(haptic_loop, BundledScriptRecordingsReplayExactly) {
  const fs::path dir = neurosim::testing::source_dir() / "tests/data/recordings";
  int found = 0;
  for (const char* name : {"press", "stroke", "circle", "retract"}) {
    const fs::path f = dir / (std::string("script_") + name + ".rec");
    ASSERT_TRUE(fs::exists(f)) << f;
    ++found;
    const auto rec = neurosim::wire::read_recording(f);
    EXPECT_EQ(rec.header.device().kind(), std::string("script:") + name);
    EXPECT_NE(rec.header.label().find("script"), std::string::npos)
        << "labelled as made with a script";
    nh::ReplayDevice dev(f.string());
    nh::testing::FakeLink link;
    nh::LoopConfig cfg;
    nh::HapticLoop loop(cfg, dev, &link, nullptr);
    loop.run_simulated(rec.samples.size() + 100);
    ASSERT_EQ(link.published.size(), rec.samples.size()) << f;
    for (std::size_t i = 0; i < rec.samples.size(); ++i) {
      const auto& p = rec.samples[i].position_m();
      ASSERT_EQ(link.published[i].position_m, Vector3d(p.x(), p.y(), p.z()))
          << f << " sample " << i;
    }
  }
  EXPECT_EQ(found, 4);
}

TEST(haptic_loop, MetricsAndSummaryJson) {
  nh::ScriptDevice dev(nh::make_script("press"));
  nh::testing::FakeLink link;
  nh::LoopConfig cfg;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  loop.run_simulated(4000);
  const nh::LoopSummary s = loop.summary();
  EXPECT_EQ(s.samples, 4000u);
  EXPECT_NEAR(s.period_p50_us, 1000, 1.0);
  EXPECT_NEAR(s.period_max_us, 1000, 1e-6);
  EXPECT_EQ(s.misses_over_1ms, 0u);
  EXPECT_NEAR(s.model_age_p99_ms, 2.0, 0.011);  // the fake answers 2 ticks late
  EXPECT_GT(s.max_force_step_n, 0);
  EXPECT_LE(s.max_force_step_n, cfg.force.max_force_step_n + 1e-12);
  const std::string json = nh::summary_json(s);
  for (const char* key : {"period_p50_us", "period_p99_us", "period_max_us", "misses_over_1ms",
                          "model_age_p99_ms", "max_force_step_n", "samples"})
    EXPECT_NE(json.find(std::string("\"") + key + "\": "), std::string::npos) << key;
  EXPECT_EQ(std::count(json.begin(), json.end(), ':'), 7) << json;
}

TEST(haptic_loop, DeviceSpecs) {
  EXPECT_EQ(nh::make_device("script:circle")->kind(), "script:circle");
  EXPECT_EQ(nh::make_device("hand:press")->kind(), "simulated_hand:press");
  EXPECT_THROW(nh::make_device("script:nope"), std::invalid_argument);
  EXPECT_THROW(nh::make_device("bogus"), std::invalid_argument);
  EXPECT_THROW(nh::make_device("replay:/nonexistent/file.rec"), std::runtime_error);
  if (!nh::omni_supported()) {
    try {
      nh::make_device("omni");
      FAIL() << "omni must not be available without OpenHaptics";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("not built in"), std::string::npos) << e.what();
    }
  }
}

// script:approach (device frame = the opening's frame, mm below): outside beside the opening,
// on the bone, over the rim, on the cerebellum, out, back; continuous (also where it repeats), at
// rest at every waypoint and
// never faster than a hand's 0.1 m/s (the tool's speed check allows 2 m/s).
TEST(haptic_loop, ApproachScriptGoesThroughTheOpeningSmoothly) {
  const auto s = nh::make_script("approach");
  const auto mm = [&](double t) -> Vector3d { return 1e3 * s->position(t); };
  EXPECT_TRUE(mm(0).isApprox(Vector3d(-32, 0, 25))) << mm(0).transpose();
  EXPECT_TRUE(mm(2.0).isApprox(Vector3d(-32, 0, 3.5))) << "down onto the bone";
  EXPECT_TRUE(mm(5.5).isApprox(Vector3d(-5, 0.5, 8.5))) << "over the rim";
  EXPECT_LT(mm(7.0).z(), -1.9) << "below the brain surface in the opening";
  EXPECT_LT(std::hypot(mm(7.0).x(), mm(7.0).y()), 15.0) << "within the 15 mm opening";
  EXPECT_TRUE(mm(10.0).isApprox(Vector3d(-6, 0.5, 25))) << "out of the opening";
  EXPECT_TRUE(mm(12.0).isApprox(mm(0))) << "back at the start: it repeats every 12 s";
  double max_speed = 0, max_jump_mm = 0;
  for (double t = 0; t < 25.0; t += 1e-3) {
    max_speed = std::max(max_speed, s->velocity(t).norm());
    max_jump_mm = std::max(max_jump_mm, (mm(t + 1e-3) - mm(t)).norm());
  }
  EXPECT_LT(max_speed, 0.1);
  EXPECT_LT(max_jump_mm, 0.1);
  for (double t : {0.5, 2.0, 3.3, 4.5, 5.5, 7.0, 8.0, 8.7, 10.0, 11.5, 12.0})
    EXPECT_LT(s->velocity(t).norm(), 1e-6) << "at rest at the waypoint t = " << t;
}

TEST(haptic_loop, RecorderDropsInsteadOfBlockingTheLoop) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_recorder");
  nh::ScriptDevice dev(nh::make_script("press"));
  nh::LoopConfig cfg;
  std::uint64_t accepted = 0;
  {
    nh::Recorder rec((dir / "r.rec").string(),
                     nh::session_header(cfg, dev, "st", "probe", "", "", "test", 0),
                     /*blocking=*/false, /*capacity=*/16);
    nh::RecordSample s;
    for (int i = 0; i < 100000; ++i) {
      s.time_s = 1e-3 * i;
      accepted += rec.push(s) ? 1 : 0;
    }
    rec.close();
    EXPECT_EQ(rec.dropped() + accepted, 100000u);
    EXPECT_EQ(rec.written(), accepted);
  }
  EXPECT_EQ(neurosim::wire::read_recording(dir / "r.rec").samples.size(), accepted);
  fs::remove_all(dir);
}

namespace {
// Runs neurosim-haptic with arguments; returns the exit status and the combined output.
int run_haptic(const std::string& args, std::string& output) {
  const std::string cmd =
      (neurosim::testing::bin_dir() / "neurosim-haptic").string() + " " + args + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (p == nullptr) return -1;
  char buf[512];
  while (std::fgets(buf, sizeof buf, p) != nullptr) output += buf;
  const int st = ::pclose(p);
  return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}
}  // namespace

TEST(haptic_loop, CommandLineRunsScriptedStationAndWritesSummary) {
  const fs::path dir = neurosim::testing::temp_dir("haptic_cli");
  std::string out;
  const int rc = run_haptic(
      "--station cli --device script:press --duration 0.3 --no-server --no-rt --summary " +
          (dir / "s.json").string() + " --record " + (dir / "r.rec").string() + " --trace " +
          (dir / "t.csv").string(),
      out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("rigid wall: 0 ticks in rigid contact"), std::string::npos) << out;
  std::ifstream f(dir / "s.json");
  const std::string json((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  EXPECT_NE(json.find("\"samples\": 300"), std::string::npos) << json;
  EXPECT_NE(json.find("\"model_age_p99_ms\": null"), std::string::npos)
      << "no server: no model age";
  EXPECT_EQ(neurosim::wire::read_recording(dir / "r.rec").samples.size(), 300u);
  EXPECT_EQ(neurosim::wire::read_recording(dir / "r.rec").header.device().kind(), "script:press");
  std::string omni;
  EXPECT_NE(run_haptic("--station cli --device omni --duration 0.1 --no-server", omni), 0);
  if (!nh::omni_supported()) {
    EXPECT_NE(omni.find("not built in"), std::string::npos) << omni;
  }
  std::string bad;
  EXPECT_EQ(run_haptic("--station cli", bad), 2) << "missing --device is a usage error";
  fs::remove_all(dir);
}

// --at-opening takes the workspace from the scene's craniotomy; refused, naming why, without a
// scene, on a scene without an opening, or beside --origin.
TEST(haptic_loop, CommandLineAtOpeningPlacesTheWorkspaceAtTheCraniotomy) {
  const std::string scenes = (neurosim::testing::source_dir() / "scenes").string();
  std::string out;
  ASSERT_EQ(run_haptic("--station cli --device script:approach --duration 0.05 --no-server "
                       "--no-rt --at-opening --scene " + scenes + "/brain_skull.scene",
                       out),
            0)
      << out;
  EXPECT_NE(out.find("workspace at the opening of 'skull': centre (0.1180, 0.0360, 0.0350) m"),
            std::string::npos)
      << out;
  std::string none;
  EXPECT_NE(run_haptic("--station cli --device script:approach --duration 0.05 --no-server "
                       "--no-rt --at-opening --scene " + scenes + "/cube_cylinder.scene",
                       none),
            0);
  EXPECT_NE(none.find("has no rigid mesh with an opening"), std::string::npos) << none;
  std::string no_scene;
  EXPECT_NE(run_haptic("--station cli --device script:approach --duration 0.05 --no-server "
                       "--no-rt --at-opening", no_scene),
            0);
  EXPECT_NE(no_scene.find("--at-opening needs --scene"), std::string::npos) << no_scene;
  std::string both;
  EXPECT_EQ(run_haptic("--station cli --device script:approach --no-server --at-opening "
                       "--origin 0,0,0 --scene " + scenes + "/brain_skull.scene", both),
            2)
      << both;
}
