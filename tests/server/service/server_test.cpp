// issue 5 "Done when": the real neurosim-server on scenes/cube_cylinder.scene (child process,
// private DDS domain on loopback, bounded): ContactModels along a scripted tool path match the
// in-process neurosim::interaction Simulation to 1e-9 relative; a late joiner gets MeshTopology
// and a FULL Deformation frame; NaN/inf/jump samples are rejected and counted in SimStatus; the
// server survives a station vanishing mid-contact and shuts down cleanly on SIGTERM.
#include "server/scene/scene.hpp"
#include "tests/server/service/service_scenarios.hpp"

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;

namespace {

st::Setup real_setup() {
  st::Setup s;
  s.exe = nt::bin_dir() / "neurosim-server";
  s.scene = nt::source_dir() / "scenes/cube_cylinder.scene";
  s.make_reference = [scene = s.scene] {
    return neurosim::interaction::Simulation::build(neurosim::scene::read_scene(scene), scene.string());
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
