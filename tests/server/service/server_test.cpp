// The service's acceptance tests: the real neurosim-server on scenes/cube_cylinder.scene
// (child process, private DDS domain on loopback, bounded): ContactModels along a scripted tool
// path match the in-process neurosim::interaction Simulation to 1e-9 relative; a late joiner
// gets MeshTopology and a FULL Deformation frame; NaN/inf/jump samples are rejected and counted
// in SimStatus; the server survives a station vanishing mid-contact and shuts down cleanly on
// SIGTERM.
#include "server/scene/compile.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <fstream>
#include <iterator>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;

namespace {

st::Setup real_setup() {
  st::Setup s;
  s.exe = nt::bin_dir() / "neurosim-server";
  s.scene = nt::source_dir() / "scenes/cube_cylinder.scene";
  s.make_reference = [scene = s.scene] {
    return neurosim::interaction::Simulation::build(neurosim::scene::load_model(scene));
  };
  s.startup_timeout_s = 240;  // meshing + factorization + columns on a shared 2-core machine
  return s;
}

}  // namespace

TEST(service_server, ScriptedPathMatchesInProcessSolverAndLateJoinerGetsTopologyAndFullFrame) {
  st::scripted_path_and_late_joiner(real_setup());
}

TEST(service_server, NanInfAndJumpSamplesRejectedAndCounted) {
  st::bad_samples(real_setup(), 0);
}

TEST(service_server, SurvivesStationVanishingMidContact) {
  st::station_vanishes(real_setup(), nt::bin_dir() / "service_test_station");
}

// Effects: the scene decides which stages are built. Same scene with coupling and deformation
// output off: no inclusion decision, no Deformation writer; with them on, both are built.
TEST(service_server, SceneWithoutCouplingRunsNoInclusionDecision) {
  const auto dir = nt::temp_dir("service_effects");
  std::ifstream in(nt::source_dir() / "scenes/cube_cylinder.scene");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string on = "effects { tier: LINEAR coupling: true tool_contact: true deformation_output: true";
  const auto at = text.find(on);
  ASSERT_NE(at, std::string::npos) << "scenes/cube_cylinder.scene effects line changed";
  text.replace(at, on.size(), "effects { tier: LINEAR coupling: false tool_contact: true deformation_output: false");
  const auto off_scene = dir / "no_coupling.scene";
  std::ofstream(off_scene) << text;
  const auto exe = nt::bin_dir() / "neurosim-server";
  st::ChildProcess with(exe, {"--scene", (nt::source_dir() / "scenes/cube_cylinder.scene").string(), "--domain",
                              std::to_string(st::private_domain()), "--duration", "1"},
                        dir / "with.log");
  st::ChildProcess without(exe, {"--scene", off_scene.string(), "--domain", std::to_string(st::private_domain()),
                                 "--duration", "1"},
                           dir / "without.log");
  ASSERT_EQ(with.wait(300), 0) << with.log();
  ASSERT_EQ(without.wait(300), 0) << without.log();
  EXPECT_NE(with.log().find("inclusion decision + coupling map"), std::string::npos) << with.log();
  EXPECT_NE(with.log().find("built: Deformation writer"), std::string::npos) << with.log();
  EXPECT_NE(without.log().find("inclusion decision: not run"), std::string::npos) << without.log();
  EXPECT_NE(without.log().find("not built: Deformation"), std::string::npos) << without.log();
}
