// The same tool path through the live neurosim-server (child process, private DDS domain on
// loopback, bounded) and through neurosim-replay (offline, in process): the poses a station sent
// are written as a recording (sample k = ToolState sequence k + 1) and replayed; every
// ContactModel the server answered equals the replay's force for that sample to 1e-9 relative
// (LINEAR: the answer depends on the pose only, not on which poses the server's clock skipped).
// On brain_skull the same holds with the skull: two stations at once, one driven into the top of
// the skull past where its raw pose would reach the brain (held outside by its proxy in the step:
// no tissue force, live or replayed), one through the craniotomy onto the cerebellum. That scene
// is the tests' 7 mm brain_skull (neurosim-model --cell-size 7: the bundled scene's skull and
// tool on a coarser brain), which halves the server's and the replay's set-up.
#include "common/clock.hpp"
#include "idl/wire/recording_io.hpp"
#include "server/interaction/surface_probe.hpp"
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

TEST(service_replay, LiveServerAndReplayGiveTheSameForces) {
  st::LiveServer live(nt::source_dir() / "scenes/cube_cylinder.scene", "replay_live", 60);
  ASSERT_TRUE(live.ses.wait_ready());
  const st::Setup& setup = live.setup;
  auto& ses = live.ses;
  auto& models = live.models;
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
  std::vector<st::RecordedPose> poses(sent);
  for (std::uint64_t k = 1; k <= sent; ++k) {
    poses[k - 1].time_s = 1e-3 * static_cast<double>(k - 1);
    poses[k - 1].tip_m = station.sent(k);
  }
  st::write_recording(rec, "cube_cylinder", "replay-1", poses);
  ASSERT_EQ(st::run_replay(setup.scene, {rec}, dir / "out", dir / "replay.log"), 0) << nt::slurp(dir / "replay.log");

  // forces.csv: one row per sample, in order (one station).
  std::vector<ni::Vec3> force;
  std::vector<bool> contact;
  for (const st::ReplayedForce& row : st::read_replay_forces(dir / "out" / "forces.csv")) {
    force.push_back(row.force_n);
    contact.push_back(row.contact);
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

namespace {

// A pose as a station sends it: tip and unit quaternion (w, x, y, z) taking the tool's +z onto the
// shaft axis.
struct SentPose {
  std::array<double, 3> tip_m{};
  std::array<double, 4> q{1, 0, 0, 0};
};

SentPose sent_pose(const ni::Vec3& tip, const ni::Vec3& axis) {
  SentPose p;
  for (int i = 0; i < 3; ++i) p.tip_m[static_cast<std::size_t>(i)] = tip[i];
  double q[4] = {1.0 + axis.z(), -axis.y(), axis.x(), 0.0};
  const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
  for (int i = 0; i < 4; ++i) p.q[static_cast<std::size_t>(i)] = q[i] / n;
  return p;
}

// Writes path[k] (sequence k + 1) at 1 kHz on its own thread, then holds the last pose 300 ms.
class PathStation {
 public:
  PathStation(st::Client& c, std::string id, std::vector<SentPose> path)
      : writer_(c.pp, c.tool_topic, id), id_(std::move(id)), path_(std::move(path)) {}
  void start() {
    thread_ = std::thread([this] {
      neurosim::wire::Sample<neurosim_ToolState> s;
      std::int64_t next = neurosim::common::monotonic_ns();
      for (std::size_t k = 0; k < path_.size() + 300; ++k) {
        const SentPose& p = path_[std::min(k, path_.size() - 1)];
        sent_.push_back(p);
        st::fill_tool(*s, id_.c_str(), sent_.size(), p.tip_m.data(), dds_time());
        for (int i = 0; i < 4; ++i) s->orientation[i] = p.q[static_cast<std::size_t>(i)];
        writer_.write(*s);
        next += 1000000;
        neurosim::common::sleep_until_ns(next);
      }
    });
  }
  void join() {
    if (thread_.joinable()) thread_.join();
  }
  ~PathStation() { join(); }
  const neurosim::wire::Writer<neurosim_ToolState>& writer() const { return writer_; }
  const std::vector<SentPose>& sent() const { return sent_; }  // after join()
  const std::string& id() const { return id_; }

 private:
  neurosim::wire::Writer<neurosim_ToolState> writer_;
  std::string id_;
  std::vector<SentPose> path_;
  std::vector<SentPose> sent_;
  std::thread thread_;
};

// What a station sent, as its recording: sample k at (k - 1) ms.
std::vector<st::RecordedPose> as_recorded(const std::vector<SentPose>& sent) {
  std::vector<st::RecordedPose> out(sent.size());
  for (std::size_t k = 0; k < sent.size(); ++k) {
    out[k].time_s = 1e-3 * static_cast<double>(k);
    out[k].tip_m = sent[k].tip_m;
    out[k].q = sent[k].q;
  }
  return out;
}

struct Replayed {
  ni::Vec3 force_n{ni::Vec3::Zero()};
  bool contact{false};
};

}  // namespace

TEST(service_replay, BrainSkullLiveServerAndReplayGiveTheSameForcesWithTheSkullHeld) {
  const auto scene_path = nt::brain7_scene("brain_skull");
  const neurosim::scene::Model scene = neurosim::scene::load_model(scene_path);
  ASSERT_FALSE(scene.rigid.empty());
  const auto obstacle = ni::RigidObstacle::build(scene.rigid);
  const double r_tip = scene.tools.front().tip_radius_m;
  // Without its skull the scene's tool would touch the brain through the bone: where (so the
  // path goes past it and the comparison can fail), and where the opening's path first touches.
  neurosim::scene::Model no_skull = scene;
  no_skull.rigid.clear();
  // Built through the run's shared cache (test_support.hpp): the live server and the replay of
  // the same brain below read its factor and boundary operator instead of factoring again.
  ni::SimulationOptions cached;
  cached.compliance_cache_dir = nt::shared_cache_dir().string();
  const auto model = ni::build_model(no_skull, cached);
  const ni::Vec3 down(0, 0, -1);
  const ni::Vec3 top = ni::top_of_obstacle(*obstacle);
  auto first_touch = [&](const std::function<ni::ToolPose(int)>& path, int max_steps) {
    auto state = ni::make_state(*model);
    std::vector<ni::ToolPose> poses(1);
    std::vector<ni::ToolContact> contacts;
    ni::StepStats stats;
    for (int k = 0; k < max_steps; ++k) {
      poses[0] = path(k);
      ni::step(*model, *state, poses, contacts, stats);
      if (contacts[0].in_contact) return k;
    }
    return -1;
  };
  // Top: from 5 mm above the skull down at 0.2 m/s; opening: along its axis at 0.5 m/s.
  const ni::Vec3 top_start = top - (r_tip + 0.005) * down;
  auto top_path = [&](int k) {
    ni::ToolPose p;
    p.tip_m = top_start + (0.0002 * k) * down;
    p.axis = -down;
    return p;
  };
  const auto& hole = scene.rigid.front().openings.front();
  auto hole_path = [&](int k) {
    ni::ToolPose p;
    p.tip_m = hole.center_m + 0.04 * hole.axis - (0.0005 * k) * hole.axis;
    p.axis = hole.axis;
    return p;
  };
  const int top_touch = first_touch(top_path, 300);
  const int hole_touch = first_touch(hole_path, 200);
  ASSERT_GT(top_touch, 0) << "no brain under the skull top within 60 mm";
  ASSERT_GT(hole_touch, 0) << "the brain is not within 100 mm along the opening's axis";
  std::vector<SentPose> top_poses, hole_poses;
  for (int k = 0; k <= top_touch + 15; ++k) top_poses.push_back(sent_pose(top_path(k).tip_m, -down));
  for (int k = 0; k <= hole_touch + 8; ++k) hole_poses.push_back(sent_pose(hole_path(k).tip_m, hole.axis));

  st::LiveServer live(scene_path, "replay_live_skull", 60);
  ASSERT_TRUE(live.ses.wait_ready());
  auto& ses = live.ses;
  auto& models = live.models;
  PathStation a(ses.client, "skull-top", top_poses), b(ses.client, "skull-hole", hole_poses);
  ASSERT_TRUE(a.writer().wait_for_readers(1, DDS_SECS(10)));
  ASSERT_TRUE(b.writer().wait_for_readers(1, DDS_SECS(10)));
  a.start();
  b.start();
  a.join();
  b.join();
  const std::size_t a_sent = a.sent().size(), b_sent = b.sent().size();
  ASSERT_TRUE(models.wait_for([&] { return models.count("skull-top") > 200 && models.count("skull-hole") > 200; }, 10))
      << ses.server.log();

  const auto dir = nt::temp_dir("service_replay_live_skull");
  st::write_recording(dir / "top.rec", "brain_skull", a.id(), as_recorded(a.sent()));
  st::write_recording(dir / "hole.rec", "brain_skull", b.id(), as_recorded(b.sent()));
  ASSERT_EQ(st::run_replay(scene_path, {dir / "top.rec", dir / "hole.rec"}, dir / "out", dir / "replay.log"), 0)
      << nt::slurp(dir / "replay.log");

  // forces.csv: per step (sample time (k - 1) ms) and station.
  std::map<std::pair<std::string, std::uint64_t>, Replayed> replayed;
  for (const st::ReplayedForce& f : st::read_replay_forces(dir / "out" / "forces.csv")) {
    const auto seq = static_cast<std::uint64_t>(std::llround(1e3 * f.time_s)) + 1;
    replayed[{f.station, seq}] = Replayed{f.force_n, f.contact};
  }
  // Both stations in every step (the shorter recording keeps its last pose).
  ASSERT_EQ(replayed.size(), 2 * std::max(a_sent, b_sent));

  std::map<std::string, std::size_t> compared, in_contact, held;
  double deepest_m = 0.0;
  for (const auto& m : models.records()) {
    if (m.station != a.id() && m.station != b.id()) continue;
    const auto it = replayed.find({m.station, m.tool_sequence});
    ASSERT_NE(it, replayed.end()) << m.station << " seq " << m.tool_sequence;
    const Replayed& r = it->second;
    ASSERT_EQ(m.in_contact, r.contact) << m.station << " seq " << m.tool_sequence;
    ++compared[m.station];
    if (m.rigid_planes > 0 && m.rigid_penetration_m > 0.0) ++held[m.station];
    if (m.station == a.id()) deepest_m = std::max(deepest_m, m.rigid_penetration_m);
    if (!m.in_contact) continue;
    ++in_contact[m.station];
    const ni::Vec3 f(m.f0[0], m.f0[1], m.f0[2]);
    EXPECT_LE((f - r.force_n).norm(), 1e-9 * r.force_n.norm())
        << m.station << " seq " << m.tool_sequence << ": server " << f.transpose() << ", replay "
        << r.force_n.transpose();
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GT(compared[a.id()], 200u);
  EXPECT_GT(compared[b.id()], 200u);
  // The top station was held by the bone past where the brain is, and never touched it.
  EXPECT_GT(held[a.id()], 50u);
  EXPECT_GT(deepest_m, 0.001);
  EXPECT_EQ(in_contact[a.id()], 0u);
  EXPECT_GT(in_contact[b.id()], 50u) << "the probe through the opening should reach the cerebellum";
  std::printf("brain_skull live vs replay: %zu + %zu ContactModels compared (top held by the bone in %zu, "
              "raw tip up to %.2f mm into the bone; %zu of the opening's in contact)\n",
              compared[a.id()], compared[b.id()], held[a.id()], 1e3 * deepest_m, in_contact[b.id()]);
}
