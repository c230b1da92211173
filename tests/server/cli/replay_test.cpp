// neurosim-replay end to end: a recorded press into the cube/cylinder scene's +x face replayed
// twice gives byte-identical forces, equal to an in-process Simulation stepped with the same
// poses; the nonlinear tier differs from the linear one; the ParaView series lists its files;
// bad input gives a clear message and a non-zero exit; a sample the live server's filter would
// reject is an error, or left out with --skip-rejected.
#include "idl/wire/recording_io.hpp"
#include "server/fem/tier.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

namespace neurosim {
namespace {

namespace fs = std::filesystem;

constexpr double kPi = 3.14159265358979323846;
constexpr const char* kHeader =
    "time_s,station,tip_x_m,tip_y_m,tip_z_m,force_x_n,force_y_n,force_z_n,in_contact";

fs::path scene_path() { return testing::source_dir() / "scenes" / "cube_cylinder.scene"; }

// Tool axis along +x (shaft outside the cube): +z rotated 90 degrees about y.
const double kQw = std::cos(kPi / 4), kQy = std::sin(kPi / 4);

// A press into the +x face at (0.1, y, 0.05) m, 4 mm deep, and back: the tip (radius 3 mm)
// starts and ends 2 mm off the face. 1 kHz samples from t0.
// bad_sample >= 0: that sample's tip is at x = 1e300 m (what the live server rejects as
// outside its workspace).
void write_press(const fs::path& file, int samples, const std::string& station = "station-a",
                 const std::string& tool = "probe", double t0 = 0.0, double y = 0.05,
                 int bad_sample = -1) {
  recording::Header h;
  h.set_scene_name("cube_cylinder");
  h.set_station_id(station);
  h.set_tool_id(tool);
  h.set_sample_rate_hz(1000.0);
  wire::RecordingWriter w(file, h);
  for (int i = 0; i < samples; ++i) {
    recording::Sample s;
    s.set_time_s(t0 + 1e-3 * i);
    const double depth = 0.006 * std::sin(kPi * i / (samples - 1));
    s.mutable_position_m()->set_x(i == bad_sample ? 1e300 : 0.105 - depth);
    s.mutable_position_m()->set_y(y);
    s.mutable_position_m()->set_z(0.05);
    s.mutable_orientation()->set_w(kQw);
    s.mutable_orientation()->set_y(kQy);
    w.write(s);
  }
  w.close();
}

struct Outcome {
  int exit_code{-1};
  std::string log;
};

Outcome run_replay(const std::string& args, const fs::path& log) {
  const std::string cmd = (testing::bin_dir() / "neurosim-replay").string() + " " + args + " > " +
                          log.string() + " 2>&1";
  const int status = std::system(cmd.c_str());
  Outcome r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.log = testing::slurp(log);
  return r;
}

struct Row {
  double t;
  std::string station;
  Eigen::Vector3d tip, force;
  bool in_contact;
};

std::vector<Row> read_forces(const fs::path& file, std::string* header = nullptr) {
  std::ifstream in(file);
  EXPECT_TRUE(in.good()) << file;
  std::string line;
  std::getline(in, line);
  if (header) *header = line;
  std::vector<Row> rows;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    EXPECT_EQ(cells.size(), 9u) << line;
    if (cells.size() != 9) break;
    Row r;
    r.t = std::stod(cells[0]);
    r.station = cells[1];
    for (int a = 0; a < 3; ++a) {
      r.tip[a] = std::stod(cells[2 + a]);
      r.force[a] = std::stod(cells[5 + a]);
    }
    r.in_contact = cells[8] == "1";
    rows.push_back(r);
  }
  return rows;
}

// One shared directory: the recordings and the linear runs are made once.
class ReplayCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(testing::temp_dir("replay_cli"));
    write_press(*dir_ / "press.rec", 300);
  }
  static void TearDownTestSuite() {
    // NEUROSIM_KEEP_TEST_DIR=1 keeps the recordings and outputs for a look.
    if (!std::getenv("NEUROSIM_KEEP_TEST_DIR")) fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path* dir_;
};
fs::path* ReplayCli::dir_ = nullptr;

TEST_F(ReplayCli, LinearRunsAreByteIdenticalAndEqualTheInProcessSimulation) {
  const fs::path& d = *dir_;
  const std::string args = "--scene " + scene_path().string() + " --recording " +
                           (d / "press.rec").string() + " --tier linear --every 50";
  for (const char* run : {"run1", "run2"}) {
    const Outcome r = run_replay(args + " --out " + (d / run).string(), d / (std::string(run) + ".log"));
    ASSERT_EQ(r.exit_code, 0) << r.log;
  }
  const std::string a = testing::slurp(d / "run1" / "forces.csv");
  ASSERT_FALSE(a.empty());
  EXPECT_EQ(a, testing::slurp(d / "run2" / "forces.csv"));
  // --cache-dir: the first run writes the host's factor and boundary operator, the second reads
  // them; both answer byte for byte as the runs without a cache.
  const fs::path cache = d / "cache";
  auto cache_files = [&] {
    std::map<std::string, fs::file_time_type> files;
    for (const auto& e : fs::directory_iterator(cache))
      files[e.path().filename().string()] = e.last_write_time();
    return files;
  };
  std::map<std::string, fs::file_time_type> written;
  for (const char* run : {"cached1", "cached2"}) {
    const Outcome r = run_replay(args + " --cache-dir " + cache.string() + " --out " +
                                     (d / run).string(),
                                 d / (std::string(run) + ".log"));
    ASSERT_EQ(r.exit_code, 0) << r.log;
    EXPECT_EQ(a, testing::slurp(d / run / "forces.csv")) << run;
    if (written.empty()) written = cache_files();
  }
  // The host's factor and the tie's boundary operator, written by the first run and only read
  // by the second (the same files, not rewritten).
  int factors = 0, couplings = 0;
  for (const auto& [name, time] : written) {
    factors += name.rfind("factor_", 0) == 0;
    couplings += name.rfind("coupling_", 0) == 0;
  }
  EXPECT_EQ(factors, 1) << cache;
  EXPECT_EQ(couplings, 1) << cache;
  EXPECT_EQ(cache_files(), written) << "the second run rewrote the cache";

  std::string header;
  const std::vector<Row> rows = read_forces(d / "run1" / "forces.csv", &header);
  EXPECT_EQ(header, kHeader);
  ASSERT_EQ(rows.size(), 300u);
  int contact = 0;
  for (const Row& r : rows) {
    EXPECT_EQ(r.station, "station-a");
    ASSERT_TRUE(r.force.allFinite());
    if (r.in_contact && r.force.norm() > 0) ++contact;
  }
  EXPECT_GT(contact, 50);
  EXPECT_FALSE(rows.front().in_contact);
  EXPECT_FALSE(rows.back().in_contact);
  // The press pushes the tool back out (+x).
  EXPECT_GT(rows[150].force.x(), 0.0);

  // The same poses stepped in process.
  scene::Model model = scene::load_model(scene_path());
  model.effects.tier = fem::Tier::kLinear;
  interaction::SimulationOptions o;
  o.tier_worker_thread = false;
  auto sim = interaction::Simulation::build(model, o);
  const wire::Recording rec = wire::read_recording(d / "press.rec");
  ASSERT_EQ(rec.samples.size(), rows.size());
  std::vector<interaction::ToolContact> contacts;
  interaction::StepStats stats;
  double max_diff = 0.0, max_force = 0.0;
  for (std::size_t i = 0; i < rec.samples.size(); ++i) {
    const auto& s = rec.samples[i];
    interaction::ToolPose p;
    p.tip_m = {s.position_m().x(), s.position_m().y(), s.position_m().z()};
    p.axis = Eigen::Vector3d::UnitX();
    p.tool = 0;
    sim->step({p}, contacts, stats);
    ASSERT_EQ(rows[i].t, s.time_s());
    ASSERT_EQ(rows[i].tip, p.tip_m);
    EXPECT_EQ(rows[i].in_contact, contacts[0].in_contact) << i;
    const Eigen::Vector3d f = contacts[0].in_contact ? contacts[0].force_n : Eigen::Vector3d::Zero();
    max_diff = std::max(max_diff, (f - rows[i].force).cwiseAbs().maxCoeff());
    max_force = std::max(max_force, f.norm());
  }
  EXPECT_GT(max_force, 0.0);
  EXPECT_LE(max_diff, 1e-12) << "largest force " << max_force << " N";

  // The series: steps 0, 50, ..., 250 and the last (299), two active meshes each.
  const std::string pvd = testing::slurp(d / "run1" / "series.pvd");
  int listed = 0;
  for (const auto& entry : fs::directory_iterator(d / "run1")) {
    if (entry.path().extension() != ".vtu") continue;
    ++listed;
    EXPECT_NE(pvd.find("file=\"" + entry.path().filename().string() + "\""), std::string::npos)
        << entry.path();
  }
  EXPECT_EQ(listed, 2 * 7);
  std::size_t datasets = 0;
  for (std::size_t pos = 0; (pos = pvd.find("<DataSet ", pos)) != std::string::npos; ++pos)
    ++datasets;
  EXPECT_EQ(datasets, static_cast<std::size_t>(listed));
  const std::string vtu = testing::slurp(d / "run1" / "cube_000003.vtu");
  EXPECT_NE(vtu.find("displacement_m"), std::string::npos);
}

TEST_F(ReplayCli, NonlinearTierFinishesWithFiniteForcesThatDifferFromLinear) {
  const fs::path& d = *dir_;
  std::vector<Row> by_tier[2];
  const char* tiers[2] = {"linear", "nonlinear"};
  for (int k = 0; k < 2; ++k) {
    const fs::path out = d / (std::string("press_") + tiers[k]);
    const Outcome r = run_replay("--scene " + scene_path().string() + " --recording " +
                                 (d / "press.rec").string() + " --tier " + tiers[k] +
                                 " --every 100 --out " + out.string(),
                             out.string() + ".log");
    ASSERT_EQ(r.exit_code, 0) << r.log;
    by_tier[k] = read_forces(out / "forces.csv");
    ASSERT_EQ(by_tier[k].size(), 300u);
  }
  double max_diff = 0.0, max_force = 0.0;
  for (std::size_t i = 0; i < 300; ++i) {
    ASSERT_TRUE(by_tier[1][i].force.allFinite());
    max_force = std::max(max_force, by_tier[1][i].force.norm());
    max_diff = std::max(max_diff, (by_tier[1][i].force - by_tier[0][i].force).norm());
  }
  EXPECT_GT(max_force, 0.0);
  EXPECT_GT(max_diff, 1e-9 * max_force);
}

// Two stations: the second starts 100.5 ms later. Steps are the union of the sample times; a
// station takes part from its first sample on, with its newest sample at every step (also
// between its own samples), and keeps its last pose after its recording ends;
// until the second starts, the replay is the single-station one, byte for byte.
TEST_F(ReplayCli, StationsAreMergedByTime) {
  const fs::path& d = *dir_;
  const fs::path second = d / "second.rec";
  write_press(second, 300, "station-b", "probe", 0.1005, 0.08);
  const std::string common = "--scene " + scene_path().string() + " --tier linear --every 1000";
  Outcome r = run_replay(common + " --recording " + (d / "press.rec").string() + " --out " +
                             (d / "one").string(),
                         d / "one.log");
  ASSERT_EQ(r.exit_code, 0) << r.log;
  r = run_replay(common + " --recording " + (d / "press.rec").string() + " --recording " +
                     second.string() + " --out " + (d / "two").string(),
                 d / "two.log");
  ASSERT_EQ(r.exit_code, 0) << r.log;
  const std::vector<Row> one = read_forces(d / "one" / "forces.csv");
  const std::vector<Row> two = read_forces(d / "two" / "forces.csv");
  // 600 distinct times; station-a in every step, station-b from its first sample (step 101) on.
  ASSERT_EQ(two.size(), 600u + 499u);
  std::size_t i = 0;
  for (; i < two.size() && two[i].t < 0.1005; ++i) {
    EXPECT_EQ(two[i].station, "station-a");
    ASSERT_LT(i, one.size());
    EXPECT_EQ(two[i].force, one[i].force) << i;
    EXPECT_EQ(two[i].t, one[i].t);
  }
  EXPECT_EQ(i, 101u);
  int b_contact = 0;
  double last_t = -1.0;
  for (; i < two.size(); ++i) {
    EXPECT_GE(two[i].t, last_t);
    last_t = two[i].t;
    ASSERT_TRUE(two[i].force.allFinite());
    if (two[i].station == "station-b") {
      EXPECT_EQ(two[i].tip.y(), 0.08);
      b_contact += two[i].in_contact ? 1 : 0;
    } else {
      ASSERT_EQ(two[i].station, "station-a");
      if (two[i].t > 0.299) {
        EXPECT_EQ(two[i].tip, one.back().tip);  // holds its last pose
      }
    }
  }
  EXPECT_GT(b_contact, 50);
}

// --max-rate thins the step times (a slow tier replays a 1 kHz recording at fewer steps); the
// linear tier's force depends only on the pose, so each kept step equals the full run's.
TEST_F(ReplayCli, MaxRateThinsTheStepsAndKeepsTheLast) {
  const fs::path& d = *dir_;
  const std::string common = "--scene " + scene_path().string() + " --recording " +
                             (d / "press.rec").string() + " --tier linear --every 1000";
  Outcome r = run_replay(common + " --out " + (d / "full").string(), d / "full.log");
  ASSERT_EQ(r.exit_code, 0) << r.log;
  r = run_replay(common + " --max-rate 100 --out " + (d / "thin").string(), d / "thin.log");
  ASSERT_EQ(r.exit_code, 0) << r.log;
  const std::vector<Row> full = read_forces(d / "full" / "forces.csv");
  const std::vector<Row> thin = read_forces(d / "thin" / "forces.csv");
  ASSERT_EQ(full.size(), 300u);
  ASSERT_GE(thin.size(), 30u);
  ASSERT_LE(thin.size(), 31u);
  EXPECT_EQ(thin.front().t, full.front().t);
  EXPECT_EQ(thin.back().t, full.back().t);
  std::size_t j = 0;
  int contacts = 0;
  for (std::size_t i = 0; i < thin.size(); ++i) {
    if (i > 0 && i + 1 < thin.size()) {
      EXPECT_GE(thin[i].t - thin[i - 1].t, 0.01 - 1e-12) << i;
    }
    while (j < full.size() && full[j].t < thin[i].t) ++j;
    ASSERT_LT(j, full.size());
    ASSERT_EQ(full[j].t, thin[i].t);
    EXPECT_LE((thin[i].force - full[j].force).norm(), 1e-9 * (1.0 + full[j].force.norm())) << i;
    contacts += thin[i].in_contact ? 1 : 0;
  }
  EXPECT_GT(contacts, 5);
  r = run_replay(common + " --max-rate -1 --out " + (d / "bad").string(), d / "bad.log");
  EXPECT_EQ(r.exit_code, 2) << r.log;
}

TEST_F(ReplayCli, UnknownTierIsAUsageError) {
  const Outcome r = run_replay("--scene " + scene_path().string() + " --recording " +
                               (*dir_ / "press.rec").string() + " --tier bogus --out " +
                               (*dir_ / "bogus").string(),
                           *dir_ / "bogus.log");
  EXPECT_EQ(r.exit_code, 2) << r.log;
  EXPECT_NE(r.log.find("bogus"), std::string::npos) << r.log;
  EXPECT_NE(r.log.find("--tier"), std::string::npos) << r.log;
}

TEST_F(ReplayCli, MissingRecordingIsNamed) {
  const fs::path missing = *dir_ / "no_such.rec";
  const Outcome r = run_replay("--scene " + scene_path().string() + " --recording " +
                               missing.string() + " --out " + (*dir_ / "missing").string(),
                           *dir_ / "missing.log");
  EXPECT_NE(r.exit_code, 0) << r.log;
  EXPECT_NE(r.log.find(missing.string()), std::string::npos) << r.log;
}

TEST_F(ReplayCli, UnknownToolIsRefusedNamingTheFile) {
  const fs::path rec = *dir_ / "wrong_tool.rec";
  write_press(rec, 5, "station-b", "scalpel");
  const Outcome r = run_replay("--scene " + scene_path().string() + " --recording " + rec.string() +
                               " --out " + (*dir_ / "wrong_tool").string(),
                           *dir_ / "wrong_tool.log");
  EXPECT_NE(r.exit_code, 0) << r.log;
  EXPECT_NE(r.log.find(rec.string()), std::string::npos) << r.log;
  EXPECT_NE(r.log.find("scalpel"), std::string::npos) << r.log;
}

// A tip at 1e300 m (a recording the live server would never have used): refused naming the file,
// the sample and the filter's cause, exit 1, no forces written; with --skip-rejected the replay
// leaves that sample out, as the server does (the station keeps its previous pose).
TEST_F(ReplayCli, SamplesTheLiveServerRejectsAreAnErrorUnlessSkipped) {
  const fs::path rec = *dir_ / "far_tip.rec";
  write_press(rec, 50, "station-far", "probe", 0.0, 0.05, 20);
  const std::string common =
      "--scene " + scene_path().string() + " --recording " + rec.string() + " --tier linear";
  Outcome r = run_replay(common + " --out " + (*dir_ / "far_refused").string(),
                         *dir_ / "far_refused.log");
  EXPECT_EQ(r.exit_code, 1) << r.log;
  EXPECT_NE(r.log.find(rec.string() + ": 1 sample(s) the live server would reject (1 workspace), "
                       "the first: sample 20 at 0.02 s (workspace)"),
            std::string::npos)
      << r.log;
  EXPECT_NE(r.log.find("--skip-rejected"), std::string::npos) << r.log;
  EXPECT_FALSE(fs::exists(*dir_ / "far_refused" / "forces.csv"));

  r = run_replay(common + " --skip-rejected --out " + (*dir_ / "far_skipped").string(),
                 *dir_ / "far_skipped.log");
  ASSERT_EQ(r.exit_code, 0) << r.log;
  EXPECT_NE(r.log.find("skipped (--skip-rejected)"), std::string::npos) << r.log;
  const auto rows = read_forces(*dir_ / "far_skipped" / "forces.csv");
  EXPECT_EQ(rows.size(), 49u);
  for (const auto& row : rows) {
    EXPECT_LT(std::abs(row.tip.x()), 1.0) << "t = " << row.t;
    EXPECT_NE(row.t, 0.02) << "the rejected sample's time is no step";
  }
}

}  // namespace
}  // namespace neurosim
