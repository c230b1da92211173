// What the replay-versus-live tests share: the live server, the poses a station sent written as a
// recording, one neurosim-replay run over recordings, and its forces.csv read back.
#pragma once

#include "idl/wire/recording_io.hpp"
#include "server/interaction/simulation.hpp"
#include "tests/server/service/service_scenarios.hpp"
#include "tests/test_support.hpp"

#include <sys/wait.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::service::testing {

// The live side of a comparison: the real neurosim-server on `scene` (start-up up to 240 s: a
// bundled scene's compliance precompute) on a private domain, and the ContactModels it answers.
// Wait for ses.wait_ready() before sending.
struct LiveServer {
  LiveServer(const std::filesystem::path& scene, const std::string& tag, double duration_s)
      : setup(make_setup(scene)), ses(setup, tag, duration_s), models(ses.client) {}
  static Setup make_setup(const std::filesystem::path& scene) {
    Setup s;
    s.exe = neurosim::testing::bin_dir() / "neurosim-server";
    s.scene = scene;
    s.startup_timeout_s = 240;
    return s;
  }
  Setup setup;  // before ses: a Session holds a reference to it
  Session ses;
  ModelCollector models;
};

// One sample of a recording: its time (unit s, from the recording's start), the tool tip (unit
// m) and the unit quaternion (w, x, y, z) taking the tool's +z onto the shaft axis.
struct RecordedPose {
  double time_s{0.0};
  std::array<double, 3> tip_m{};
  std::array<double, 4> q{1, 0, 0, 0};
};

// Writes `poses` as the recording of station `station_id` on scene `scene_name` (tool "probe",
// nominal 1 kHz); sample k gets tool sequence k + 1.
inline void write_recording(const std::filesystem::path& file, const std::string& scene_name,
                            const std::string& station_id, const std::vector<RecordedPose>& poses) {
  neurosim::recording::Header h;
  h.set_scene_name(scene_name);
  h.set_station_id(station_id);
  h.set_tool_id("probe");
  h.set_sample_rate_hz(1000.0);
  neurosim::wire::RecordingWriter w(file, h);
  for (std::size_t k = 0; k < poses.size(); ++k) {
    neurosim::recording::Sample s;
    s.set_time_s(poses[k].time_s);
    s.mutable_position_m()->set_x(poses[k].tip_m[0]);
    s.mutable_position_m()->set_y(poses[k].tip_m[1]);
    s.mutable_position_m()->set_z(poses[k].tip_m[2]);
    s.mutable_orientation()->set_w(poses[k].q[0]);
    s.mutable_orientation()->set_x(poses[k].q[1]);
    s.mutable_orientation()->set_y(poses[k].q[2]);
    s.mutable_orientation()->set_z(poses[k].q[3]);
    s.set_tool_sequence(k + 1);
    w.write(s);
  }
  w.close();
}

// Runs neurosim-replay on `scene` with `recordings` into `out` (its output to `log`); returns its
// exit status (-1 if it did not exit normally).
inline int run_replay(const std::filesystem::path& scene, const std::vector<std::filesystem::path>& recordings,
                      const std::filesystem::path& out, const std::filesystem::path& log) {
  std::string cmd = (neurosim::testing::bin_dir() / "neurosim-replay").string() + " --scene " + scene.string();
  for (const auto& r : recordings) cmd += " --recording " + r.string();
  // The run's shared factor cache (test_support.hpp): the live server of the same scene filled it.
  cmd += " --cache-dir " + neurosim::testing::shared_cache_dir().string();
  cmd += " --out " + out.string() + " > " + log.string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// One row of neurosim-replay's forces.csv: sample time (unit s), station, force (unit N), contact.
struct ReplayedForce {
  double time_s{0.0};
  std::string station;
  interaction::Vec3 force_n{interaction::Vec3::Zero()};
  bool contact{false};
};

// forces.csv's rows in file order; throws std::runtime_error naming the row if one is malformed.
inline std::vector<ReplayedForce> read_replay_forces(const std::filesystem::path& csv_path) {
  std::ifstream csv(csv_path);
  std::string line;
  if (!std::getline(csv, line)) throw std::runtime_error(csv_path.string() + ": empty");
  std::vector<ReplayedForce> out;
  while (std::getline(csv, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (cells.size() != 9u) throw std::runtime_error(csv_path.string() + ": bad row " + line);
    ReplayedForce r;
    r.time_s = std::stod(cells[0]);
    r.station = cells[1];
    r.force_n = interaction::Vec3(std::stod(cells[5]), std::stod(cells[6]), std::stod(cells[7]));
    r.contact = cells[8] == "1" || cells[8] == "true";
    out.push_back(r);
  }
  return out;
}

}  // namespace neurosim::service::testing
