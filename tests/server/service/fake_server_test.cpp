// The service's DDS plumbing against the test-only FakeSimulation (analytic half-space spring),
// through the real server code in a child process (service_test_fake_server): scripted path vs
// the in-process fake, late joiner, rejected samples and refused stations, a station vanishing
// mid-contact, effects (no viewer → no full-field solves; deformation off → not built), bad
// scene, --duration, --tier (SimStatus.tier and tier_update_rate_hz from the simulation, unknown
// tier refused). Each test starts its own server on a private DDS domain.
#include "server/scene/compile.hpp"
#include "server/service/server.hpp"
#include "tests/server/service/fake_simulation.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <fstream>
#include <regex>
#include <sstream>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;

namespace {

st::Setup fake_setup() {
  st::Setup s;
  s.exe = nt::bin_dir() / "service_test_fake_server";
  s.scene = nt::source_dir() / "tests/server/service/data/fake_box.scene";
  s.make_reference = [scene = s.scene] {
    return st::make_fake(neurosim::scene::load_model(scene));
  };
  s.startup_timeout_s = 20;
  return s;
}

long displacement_calls(const std::string& log) {
  std::smatch m;
  const std::regex re("fake simulation: ([0-9]+) displacements calls");
  if (!std::regex_search(log, m, re)) return -1;
  return std::stol(m[1]);
}

}  // namespace

TEST(service_fake, ScriptedPathMatchesInProcessAndLateJoinerGetsTopologyAndFullFrame) {
  st::scripted_path_and_late_joiner(fake_setup());
}

TEST(service_fake, BadSamplesRejectedAndCountedExtraStationRefused) {
  st::bad_samples(fake_setup(), 2);
}

TEST(service_fake, SurvivesStationVanishingMidContact) {
  st::station_vanishes(fake_setup(), nt::bin_dir() / "service_test_station");
}

TEST(service_fake, NoViewerMeansNoFullFieldSolves) {
  const auto setup = fake_setup();
  st::Session ses(setup, "noviewer", 1.5);
  ASSERT_TRUE(ses.wait_ready());
  st::StationThread s(ses.client, "s", [&](double) {
    return std::array<double, 3>{0.102, 0.05, 0.05};
  }, 1.0);
  s.wait_done();
  EXPECT_EQ(ses.server.wait(15), 0) << "--duration must stop the server by itself\n" << ses.server.log();
  const std::string log = ses.server.log();
  EXPECT_EQ(displacement_calls(log), 0) << log;
  EXPECT_NE(log.find("full-field solves only while a viewer is matched"), std::string::npos) << log;
}

TEST(service_fake, DeformationOffIsNotBuilt) {
  const auto dir = nt::temp_dir("service_deform_off");
  auto scene = neurosim::scene::read_scene(fake_setup().scene);
  std::ifstream in(fake_setup().scene);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  text = std::regex_replace(text, std::regex("deformation_output: true"), "deformation_output: false");
  const auto path = dir / "no_deformation.scene";
  std::ofstream(path) << text;
  auto setup = fake_setup();
  setup.scene = path;
  st::Session ses(setup, "deformoff", 30);
  ASSERT_TRUE(ses.wait_ready());
  // A viewer that subscribes anyway gets nothing.
  neurosim::wire::Reader<neurosim_Deformation> viewer(ses.client.pp, ses.client.deform_topic);
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  EXPECT_EQ(ses.server.signal_and_wait(SIGINT, 15), 0) << "SIGINT: clean exit\n" << ses.server.log();
  const std::string log = ses.server.log();
  EXPECT_NE(log.find("signal received"), std::string::npos) << log;
  EXPECT_NE(log.find("not built: Deformation"), std::string::npos) << log;
  EXPECT_EQ(displacement_calls(log), 0) << log;
  EXPECT_TRUE(viewer.take().empty());
}

TEST(service_fake, BadSceneExitsWithErrorNamingFileAndField) {
  const auto dir = nt::temp_dir("service_bad_scene");
  std::ifstream in(fake_setup().scene);
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  text = std::regex_replace(text, std::regex("poisson_ratio: 0.4"), "poisson_ratio: 0.7");
  const auto path = dir / "bad.scene";
  std::ofstream(path) << text;
  st::ChildProcess p(nt::bin_dir() / "service_test_fake_server", {"--scene", path.string(), "--duration", "5"},
                     dir / "log.txt");
  EXPECT_EQ(p.wait(20), 1);
  const std::string log = p.log();
  EXPECT_NE(log.find("bad.scene"), std::string::npos) << log;
  EXPECT_NE(log.find("meshes[0].material"), std::string::npos) << log;
}

// --tier overrides the scene's LINEAR; SimStatus carries the simulation's tier and its update
// rate, refilled at every publish: the fake reports 0 Hz until it has stepped and
// kTierUpdateRateHz after, so a server that fills the fields once (or never) fails here.
TEST(service_fake, TierFromCommandLineAndItsUpdateRateReachSimStatus) {
  auto setup = fake_setup();
  setup.server_args = {"--tier", "nonlinear"};
  st::Session ses(setup, "tier", 30);
  ASSERT_TRUE(ses.wait_ready());
  // No station yet: nothing stepped, no equilibrium update.
  EXPECT_TRUE(ses.status.wait_for(
      [](const neurosim_SimStatus& s) { return s.tier == neurosim_TIER_NONLINEAR && s.tier_update_rate_hz == 0.0; },
      5))
      << "tier " << ses.status.last_text << "\n" << ses.server.log();
  st::StationThread station(ses.client, "tier-1", [&](double) {
    return std::array<double, 3>{0.102, 0.05, 0.05};
  }, 1.0);
  double rate = -1;
  int tier = -1;
  EXPECT_TRUE(ses.status.wait_for(
      [&](const neurosim_SimStatus& s) {
        rate = s.tier_update_rate_hz;
        tier = static_cast<int>(s.tier);
        return s.tier == neurosim_TIER_NONLINEAR && s.tier_update_rate_hz == st::FakeSimulation::kTierUpdateRateHz;
      },
      10))
      << "SimStatus tier " << tier << " (NONLINEAR is " << neurosim_TIER_NONLINEAR << "), tier_update_rate_hz "
      << rate << " (the fake reports " << st::FakeSimulation::kTierUpdateRateHz << ")\n" << ses.server.log();
  station.wait_done();
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
  const std::string log = ses.server.log();
  EXPECT_NE(log.find("tier NONLINEAR (from --tier nonlinear; the scene's effects.tier is LINEAR)"), std::string::npos)
      << log;
  EXPECT_NE(log.find("tier NONLINEAR (from --tier)"), std::string::npos) << log;
}

// Without --tier the scene's tier runs (LINEAR: no equilibrium updates, 0 Hz, also after steps).
TEST(service_fake, TierDefaultsToTheScenes) {
  st::Session ses(fake_setup(), "tier_default", 30);
  ASSERT_TRUE(ses.wait_ready());
  st::StationThread station(ses.client, "tier-2", [&](double) {
    return std::array<double, 3>{0.102, 0.05, 0.05};
  }, 0.6);
  station.wait_done();
  // A status published after the station's steps (its stations list names it).
  EXPECT_TRUE(ses.status.wait_for(
      [](const neurosim_SimStatus& s) {
        const auto* b = st::find_station(s, "tier-2");
        return b != nullptr && b->samples_accepted > 0 && s.tier == neurosim_TIER_LINEAR &&
               s.tier_update_rate_hz == 0.0;
      },
      10))
      << ses.status.last_text << "\n" << ses.server.log();
  EXPECT_EQ(ses.server.signal_and_wait(SIGTERM, 15), 0) << ses.server.log();
  const std::string log = ses.server.log();
  EXPECT_NE(log.find("tier LINEAR (from the scene's effects.tier)"), std::string::npos) << log;
  EXPECT_NE(log.find("tier LINEAR (from scene)"), std::string::npos) << log;
}

TEST(service_fake, UnknownTierIsAUsageError) {
  const auto dir = nt::temp_dir("service_bad_tier");
  st::ChildProcess p(nt::bin_dir() / "service_test_fake_server",
                     {"--scene", fake_setup().scene.string(), "--tier", "hyperelastic", "--duration", "5"},
                     dir / "log.txt");
  EXPECT_EQ(p.wait(20), 2);
  const std::string log = p.log();
  EXPECT_NE(log.find("--tier"), std::string::npos) << log;
  EXPECT_NE(log.find("hyperelastic"), std::string::npos) << log;
  EXPECT_NE(log.find("linear or nonlinear"), std::string::npos) << log;
  EXPECT_EQ(log.find("simulation built"), std::string::npos) << "refused before building\n" << log;
}

TEST(service_fake, WithdrawnCorotationalTierIsAUsageError) {
  const auto dir = nt::temp_dir("service_corot_tier");
  st::ChildProcess p(nt::bin_dir() / "service_test_fake_server",
                     {"--scene", fake_setup().scene.string(), "--tier", "corotational", "--duration", "5"},
                     dir / "log.txt");
  EXPECT_EQ(p.wait(20), 2);
  const std::string log = p.log();
  EXPECT_NE(log.find("withdrawn"), std::string::npos) << log;
  EXPECT_NE(log.find("NONLINEAR"), std::string::npos) << log;
  EXPECT_EQ(log.find("simulation built"), std::string::npos) << "refused before building\n" << log;
}

// A simulation that runs another tier than the scene asks for is refused (SimStatus would
// otherwise report a tier nobody asked for). In process: the check is in the constructor.
TEST(service_fake, SimulationRunningAnotherTierIsRefused) {
  const auto model = neurosim::scene::load_model(fake_setup().scene);
  ASSERT_EQ(model.effects.tier, neurosim::scene::Tier::kLinear);
  std::ostringstream log;
  try {
    neurosim::service::Server server(
        model, std::make_unique<st::FakeSimulation>(model, neurosim::scene::Tier::kCorotational), {}, log);
    FAIL() << "accepted a simulation running COROTATIONAL for a LINEAR scene\n" << log.str();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("runs tier COROTATIONAL, not the tier asked for: LINEAR"), std::string::npos)
        << e.what();
  }
}
