// A press into the viscoelastic brain (scenes/brain_viscoelastic.scene, LINEAR tier) through the
// live neurosim-server and through neurosim-replay: time enters the step of a relaxing body, so
// the replay must step exactly the poses and the sample times the server stepped. The server
// steps the newest pose of a station at the newest source time (from the first pose it saw), and
// may skip a pose that a newer one replaced before its step; so the station here sends in lock
// step (pose k + 1 only once a ContactModel answered pose k): every pose sent is stepped, at its
// own source time, and the server's deadline steps between two poses repeat the same pose at the
// same time (dt = 0: the history does not move). The recording of what was sent (sample time =
// source time - the first one, as the server forms it) replayed offline gives every ContactModel's
// force to 1e-9 relative; two replays of it give byte-identical forces.csv (%.17g: bit-identical
// forces); and the held press relaxed (the comparison covers time, not only the pose).
#include "common/clock.hpp"
#include "idl/wire/recording_io.hpp"
#include "server/scene/compile.hpp"
#include "tests/server/service/replay_fixture.hpp"
#include "tests/server/service/service_scenarios.hpp"

#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <sys/wait.h>
#include <thread>

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
namespace ni = neurosim::interaction;

namespace {

// forces.csv's rows by sample time (one station).
std::map<double, st::ReplayedForce> forces_by_time(const std::filesystem::path& csv_path) {
  std::map<double, st::ReplayedForce> out;
  for (const st::ReplayedForce& r : st::read_replay_forces(csv_path)) out[r.time_s] = r;
  return out;
}

}  // namespace

TEST(service_replay_viscoelastic, LiveServerAndReplayGiveTheSameRelaxingForces) {
  const auto scene_path = nt::source_dir() / "scenes/brain_viscoelastic.scene";
  const neurosim::scene::Model scene = neurosim::scene::load_model(scene_path);
  const int brain = scene.find_mesh("brain");
  ASSERT_GE(brain, 0);
  ASSERT_FALSE(scene.meshes[static_cast<std::size_t>(brain)].material.viscoelastic.empty());
  const double r_tip = scene.tools.front().tip_radius_m;
  // Straight down onto the brain's highest vertex (the sphere first touches it there), from 2 mm
  // above: 0.02 mm per pose to 3 mm deep, then held.
  ni::Vec3 top = scene.meshes[static_cast<std::size_t>(brain)].mesh.vertices().front();
  for (const auto& v : scene.meshes[static_cast<std::size_t>(brain)].mesh.vertices())
    if (v.z() > top.z()) top = v;
  constexpr int kRamp = 250, kHold = 250;
  auto tip_at = [&](int k) {
    const double depth = -0.002 + 0.00002 * std::min(k, kRamp);
    return ni::Vec3(top.x(), top.y(), top.z() + r_tip - depth);
  };

  st::LiveServer live(scene_path, "replay_live_visco", 90);
  ASSERT_TRUE(live.ses.wait_ready());
  auto& ses = live.ses;
  auto& models = live.models;
  const std::string id = "visco-1";
  neurosim::wire::Writer<neurosim_ToolState> writer(ses.client.pp, ses.client.tool_topic, id);
  ASSERT_TRUE(writer.wait_for_readers(1, DDS_SECS(10)));

  // Lock step: pose k + 1 is sent once pose k was answered. In the hold, 4 ms more between poses
  // (the press relaxes over a second; the server repeats each pose at its time meanwhile).
  // First the tool hovers at its start until the server's column worker has solved every column
  // within its reach (SimStatus.columns_solved_ahead the same in two statuses a second apart):
  // the press (5 mm, inside that reach) then never meets a column not ready, whose fallback the
  // replay (columns solved in the step) would not take.
  std::vector<ni::Vec3> sent;
  std::vector<std::int64_t> source_ns;
  neurosim::wire::Sample<neurosim_ToolState> s;
  std::uint64_t solved = 0, solved_before = 0, statuses = 0;
  int hover = 0;
  const auto hover_start = neurosim::common::Clock::now();
  for (int k = 0; hover + kRamp + kHold > k; ++k) {
    if (k == hover && (statuses < 3 || solved == 0 || solved != solved_before)) {
      ASSERT_LT(neurosim::common::seconds_since(hover_start), 90.0)
          << "the column worker did not settle: " << ses.status.last_text;
      ++hover;
      ses.status.wait_for([&](const neurosim_SimStatus& st) {
        ++statuses;
        solved_before = solved;
        solved = st.columns_solved_ahead;
        return true;
      }, 0.01);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    const ni::Vec3 p = tip_at(std::max(0, k - hover));
    const double pos[3] = {p.x(), p.y(), p.z()};
    const std::int64_t t = dds_time();
    const std::uint64_t seq = static_cast<std::uint64_t>(k + 1);
    st::fill_tool(*s, id.c_str(), seq, pos, t);
    sent.push_back(p);
    source_ns.push_back(t);
    // ToolState is best effort: a pose lost on the way is sent again (the same sample; if the
    // first did arrive, the server's filter rejects the copy and keeps the pose).
    bool answered = false;
    for (int attempt = 0; attempt < 200 && !answered; ++attempt) {
      writer.write(*s);
      answered = models.wait_for([&] { return models.newest_sequence(id) >= seq; }, 0.05);
    }
    ASSERT_TRUE(answered) << "no ContactModel for pose " << seq << "\n" << ses.server.log();
    if (k - hover >= kRamp) std::this_thread::sleep_for(std::chrono::milliseconds(4));
  }
  // Not one step took the fallback of a column not ready (then the comparison below holds).
  const std::uint64_t end_steps = ses.status.last_steps;
  std::uint64_t not_ready = 1;
  ASSERT_TRUE(ses.status.wait_for([&](const neurosim_SimStatus& st) {
    not_ready = st.columns_not_ready;
    return st.steps > end_steps;
  }, 10)) << ses.status.last_text;
  EXPECT_EQ(not_ready, 0u) << "steps met contact columns not ready";

  // What the station sent, as its recording: sample k at its source time minus the first one.
  const auto dir = nt::temp_dir("service_replay_live_visco");
  const auto rec = dir / "visco-1.rec";
  std::vector<double> time_s(sent.size());
  std::vector<st::RecordedPose> poses(sent.size());
  for (std::size_t k = 0; k < sent.size(); ++k) {
    time_s[k] = 1e-9 * static_cast<double>(source_ns[k] - source_ns[0]);
    poses[k].time_s = time_s[k];
    poses[k].tip_m = {sent[k].x(), sent[k].y(), sent[k].z()};
  }
  st::write_recording(rec, "brain_viscoelastic", id, poses);
  ASSERT_EQ(st::run_replay(scene_path, {rec}, dir / "out1", dir / "replay1.log"), 0) << nt::slurp(dir / "replay1.log");
  ASSERT_EQ(st::run_replay(scene_path, {rec}, dir / "out2", dir / "replay2.log"), 0) << nt::slurp(dir / "replay2.log");
  // Deterministic: the two replays wrote the same bytes.
  const std::string csv1 = nt::slurp(dir / "out1" / "forces.csv"), csv2 = nt::slurp(dir / "out2" / "forces.csv");
  ASSERT_FALSE(csv1.empty());
  EXPECT_EQ(csv1, csv2) << "two replays of one recording differ";
  const std::map<double, st::ReplayedForce> replayed = forces_by_time(dir / "out1" / "forces.csv");
  ASSERT_EQ(replayed.size(), sent.size()) << "one step per sample time";

  // Every ContactModel against the replay at its pose's sample time.
  std::size_t compared = 0, in_contact = 0;
  for (const auto& m : models.records()) {
    if (m.station != id) continue;
    ASSERT_GE(m.tool_sequence, 1u);
    ASSERT_LE(m.tool_sequence, sent.size());
    const auto it = replayed.find(time_s[m.tool_sequence - 1]);
    ASSERT_NE(it, replayed.end()) << "seq " << m.tool_sequence;
    const st::ReplayedForce& r = it->second;
    ASSERT_EQ(m.in_contact, r.contact) << "seq " << m.tool_sequence;
    ++compared;
    if (!m.in_contact) continue;
    ++in_contact;
    const ni::Vec3 f(m.f0[0], m.f0[1], m.f0[2]);
    EXPECT_LE((f - r.force_n).norm(), 1e-9 * r.force_n.norm())
        << "seq " << m.tool_sequence << ": server " << f.transpose() << ", replay " << r.force_n.transpose();
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GE(compared, sent.size());
  EXPECT_GT(in_contact, 300u);
  ASSERT_EQ(sent.size(), static_cast<std::size_t>(hover + kRamp + kHold));
  // The held press relaxed (tau = 0.5 s and 50 s over the hold): time was compared, not only poses.
  const double f_ramp = replayed.at(time_s[hover + kRamp - 1]).force_n.norm();
  const double f_end = replayed.at(time_s.back()).force_n.norm();
  EXPECT_GT(f_ramp, 0.0);
  EXPECT_LT(f_end, 0.9 * f_ramp);
  std::printf("brain_viscoelastic live vs replay: %zu ContactModels compared (%zu in contact) for %zu poses "
              "over %.3f s (%d hovering while %llu columns were solved ahead); force at the end of the "
              "press %.5f N, after the hold %.5f N\n",
              compared, in_contact, sent.size(), time_s.back(), hover,
              static_cast<unsigned long long>(solved), f_ramp, f_end);
}
