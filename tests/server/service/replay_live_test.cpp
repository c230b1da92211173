// The same tool path through the live neurosim-server (child process, private DDS domain on
// loopback, bounded) and through neurosim-replay (offline, in process): the poses a station sent
// are written as a recording (sample k = ToolState sequence k + 1) and replayed; every
// ContactModel the server answered equals the replay's force for that sample to 1e-9 relative
// (LINEAR: the answer depends on the pose only, not on which poses the server's clock skipped).
#include "idl/wire/recording_io.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <sys/wait.h>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace ni = neurosim::interaction;

TEST(service_replay, LiveServerAndReplayGiveTheSameForces) {
  st::Setup setup;
  setup.exe = nt::bin_dir() / "neurosim-server";
  setup.scene = nt::source_dir() / "scenes/cube_cylinder.scene";
  setup.startup_timeout_s = 240;
  st::Session ses(setup, "replay_live", 60);
  ASSERT_TRUE(ses.wait_ready());
  st::ModelCollector models(ses.client);
  // Into the +x face from 4 mm outside to 3 mm in over 1.2 s, then held (tip radius 3 mm).
  const double r = setup.tip_radius_m, x0 = 0.1 + r + 0.004, x1 = 0.1 + r - 0.003;
  auto path = [&](double t) -> std::array<double, 3> {
    const double a = std::min(1.0, t / 1.2);
    return {x0 - a * (x0 - x1), 0.05, 0.05};
  };
  st::StationThread station(ses.client, "replay-1", path, 1.5);
  ASSERT_TRUE(station.writer().wait_for_readers(1, DDS_SECS(10)));
  station.wait_done();
  ASSERT_TRUE(models.wait_for([&] { return models.count("replay-1") > 200; }, 10))
      << ses.server.log();

  // What the station sent, as a recording (identity orientation: the tool axis is +z).
  const auto dir = nt::temp_dir("service_replay_live");
  const auto rec = dir / "replay-1.rec";
  const std::uint64_t sent = station.sent_count();
  {
    neurosim::recording::Header h;
    h.set_scene_name("cube_cylinder");
    h.set_station_id("replay-1");
    h.set_tool_id("probe");
    h.set_sample_rate_hz(1000.0);
    neurosim::wire::RecordingWriter w(rec, h);
    for (std::uint64_t k = 1; k <= sent; ++k) {
      const auto p = station.sent(k);
      neurosim::recording::Sample s;
      s.set_time_s(1e-3 * static_cast<double>(k - 1));
      s.mutable_position_m()->set_x(p[0]);
      s.mutable_position_m()->set_y(p[1]);
      s.mutable_position_m()->set_z(p[2]);
      s.mutable_orientation()->set_w(1.0);
      s.set_tool_sequence(k);
      w.write(s);
    }
    w.close();
  }
  const std::string cmd = (nt::bin_dir() / "neurosim-replay").string() + " --scene " +
                          setup.scene.string() + " --recording " + rec.string() + " --out " +
                          (dir / "out").string() + " > " + (dir / "replay.log").string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << nt::slurp(dir / "replay.log");

  // forces.csv: one row per sample, in order (one station).
  std::ifstream csv(dir / "out" / "forces.csv");
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  std::vector<ni::Vec3> force;
  std::vector<bool> contact;
  while (std::getline(csv, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 9u) << line;
    force.emplace_back(std::stod(cells[5]), std::stod(cells[6]), std::stod(cells[7]));
    contact.push_back(cells[8] == "1" || cells[8] == "true");
  }
  ASSERT_EQ(force.size(), sent);

  std::size_t compared = 0, in_contact = 0;
  for (const auto& m : models.records()) {
    if (m.station != "replay-1") continue;
    ASSERT_GE(m.tool_sequence, 1u);
    ASSERT_LE(m.tool_sequence, sent);
    const std::size_t k = m.tool_sequence - 1;
    ASSERT_EQ(m.in_contact, contact[k]) << "seq " << m.tool_sequence;
    ++compared;
    if (!m.in_contact) continue;
    ++in_contact;
    const ni::Vec3 f(m.f0[0], m.f0[1], m.f0[2]);
    EXPECT_LE((f - force[k]).norm(), 1e-9 * force[k].norm())
        << "seq " << m.tool_sequence << ": server " << f.transpose() << ", replay "
        << force[k].transpose();
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GT(compared, 200u);
  EXPECT_GT(in_contact, 50u);
  std::printf("live vs replay: %zu ContactModels compared (%zu in contact), %llu poses sent\n",
              compared, in_contact, static_cast<unsigned long long>(sent));
}
