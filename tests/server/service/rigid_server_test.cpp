// neurosim-server with rigid obstacles (brain_skull: the skull with a suboccipital craniotomy; the
// tests' 7 mm brain, the demo's approach on the bundled scene), child process on a private DDS
// domain on loopback, bounded: a station driving the
// probe into the skull at 0.5 m/s gets ContactModel.rigid_planes whose penetration follows the
// device 10 mm deep while the server's physics never touches the brain behind the bone (the raw
// pose would); through the opening the probe reaches the brain unblocked, with the forces of the
// in-process Simulation stepped with the same poses. A scene without rigid meshes builds no
// obstacle and sends no planes. The demo's approach station (neurosim-haptic script:approach)
// slides on the bone and presses the cerebellum through the opening.
#include "haptic_client/force_model.hpp"
#include "server/interaction/rigid_obstacle.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/surface_probe.hpp"
#include "server/scene/compile.hpp"
#include "tests/server/service/service_scenarios.hpp"

namespace st = neurosim::service::testing;
namespace nt = neurosim::testing;
using namespace neurosim;

namespace {

struct PlaneRecord {
  double point[3], normal[3], penetration;
};
struct Record {
  std::uint64_t seq{0};
  bool in_contact{false};
  double f0[3]{};
  std::string mesh;
  std::vector<PlaneRecord> planes;
};

// One station writing a scripted path (tip and shaft axis) at 1 kHz, and every ContactModel it
// gets, with its rigid planes.
class Station {
 public:
  Station(st::Client& c, std::string id) : writer_(c.pp, c.tool_topic, id), reader_(c.pp, c.model_topic),
                                           ws_(c.pp), id_(std::move(id)) {
    ws_.attach_data(reader_, 1);
  }
  // Sends path(k) for k = 0..steps-1, one per ms, taking the models as they come; then waits a
  // little for the last answers.
  void run(const std::function<interaction::ToolPose(int)>& path, int steps) {
    EXPECT_TRUE(writer_.wait_for_readers(1, DDS_SECS(10)));
    wire::Sample<neurosim_ToolState> s;
    std::int64_t next = common::monotonic_ns();
    for (int k = 0; k < steps + 300; ++k) {
      const interaction::ToolPose p = path(std::min(k, steps - 1));  // then hold the last pose
      sent_.push_back(p);
      const double pos[3] = {p.tip_m.x(), p.tip_m.y(), p.tip_m.z()};
      st::fill_tool(*s, id_.c_str(), sent_.size(), pos, dds_time());
      // Orientation taking the tool's +z onto the axis: q = (1 + z.a, z x a), normalised.
      const interaction::Vec3& a = p.axis;
      double q[4] = {1.0 + a.z(), -a.y(), a.x(), 0.0};
      const double n = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
      for (int i = 0; i < 4; ++i) s->orientation[i] = q[i] / n;
      writer_.write(*s);
      take();
      next += 1000000;
      common::sleep_until_ns(next);
    }
    const auto t0 = st::Clock::now();
    while (st::seconds_since(t0) < 1.0) {
      ws_.wait(DDS_MSECS(20));
      take();
    }
  }
  const std::vector<Record>& records() const { return recs_; }
  const interaction::ToolPose& sent(std::uint64_t seq) const { return sent_.at(seq - 1); }

 private:
  void take() {
    for (const auto& rx : reader_.take()) {
      if (!rx.valid() || std::string(rx.data.station_id) != id_) continue;
      const auto& d = rx.data;
      Record r;
      r.seq = d.tool_sequence;
      r.in_contact = d.in_contact;
      for (int i = 0; i < 3; ++i) r.f0[i] = d.f0_n[i];
      r.mesh = d.contact_mesh_id;
      for (std::uint32_t j = 0; j < d.rigid_planes._length; ++j) {
        const auto& p = d.rigid_planes._buffer[j];
        r.planes.push_back({{p.point_m[0], p.point_m[1], p.point_m[2]},
                            {p.normal[0], p.normal[1], p.normal[2]},
                            p.penetration_m});
      }
      recs_.push_back(std::move(r));
    }
  }
  wire::Writer<neurosim_ToolState> writer_;
  wire::Reader<neurosim_ContactModel> reader_;
  wire::Waitset ws_;
  std::string id_;
  std::vector<interaction::ToolPose> sent_;
  std::vector<Record> recs_;
};

// The tests' 7 mm brain_skull (neurosim-model --cell-size 7: the bundled scene's skull, opening
// and tool on a coarser brain): the server's and the in-process reference's set-up is the cost
// of these tests, and nothing they check depends on the brain's cell size. The demo's approach
// below runs on the bundled scene.
const scene::Model& skull_scene() {
  static const scene::Model m = scene::load_model(nt::brain7_scene("brain_skull"));
  return m;
}

st::Setup skull_setup() {
  st::Setup s;
  s.exe = nt::bin_dir() / "neurosim-server";
  s.scene = nt::brain7_scene("brain_skull");
  s.make_reference = [] { return interaction::Simulation::build(skull_scene()); };
  s.startup_timeout_s = 240;
  return s;
}

double max_penetration(const Record& r) {
  double p = 0.0;
  for (const auto& q : r.planes) p = std::max(p, q.penetration);
  return p;
}

}  // namespace

TEST(service_rigid, DrivenIntoTheSkullHeldOutsideWhileTheDeviceGoesTenMillimetresDeep) {
  const st::Setup setup = skull_setup();
  st::Session ses(setup, "rigid_skull", 30);
  // The raw pose's physics: the scene without its skull (the Simulation holds a tool outside it).
  scene::Model no_skull = skull_scene();
  no_skull.rigid.clear();
  auto ref = interaction::Simulation::build(no_skull);
  const auto obstacle = interaction::RigidObstacle::build(skull_scene().rigid);
  ASSERT_TRUE(ses.wait_ready());
  EXPECT_NE(ses.server.log().find("built: rigid obstacles (7538 triangles)"), std::string::npos)
      << ses.server.log();
  // Straight down onto the top of the skull: the line's entry into the bone.
  const mesh::Vec3 down(0, 0, -1);
  const mesh::Vec3 surface = interaction::top_of_obstacle(*obstacle);
  const double r_tip = skull_scene().tools.front().tip_radius_m;
  const mesh::Vec3 start = surface - (r_tip + 0.005) * down;
  auto at_depth = [&](double depth_m) {  // depth of the tip centre below the outer table
    interaction::ToolPose p;
    p.tip_m = surface + depth_m * down;
    p.axis = -down;
    return p;
  };
  // Where the raw pose would touch the brain through the bone (in-process, no obstacle): the
  // path goes 10 mm deep, or 3 mm past that point if it is deeper, so the test can fail.
  double brain_depth = -1.0;
  {
    std::vector<interaction::ToolPose> poses(1);
    std::vector<interaction::ToolContact> contacts;
    interaction::StepStats stats;
    for (double d = 0.0; d <= 0.03 && brain_depth < 0; d += 0.0005) {
      poses[0] = at_depth(d);
      ref->step(poses, contacts, stats);
      if (contacts[0].in_contact) brain_depth = d;
    }
  }
  ASSERT_GT(brain_depth, 0.0) << "no brain under the skull top within 30 mm";
  const double end_depth = std::max(0.010, brain_depth + 0.003);
  const int steps = static_cast<int>((r_tip + 0.005 + end_depth) / 0.0005) + 1;  // 0.5 m/s
  auto path = [&](int k) {
    interaction::ToolPose p;
    p.tip_m = start + (0.0005 * k) * down;
    p.axis = -down;
    return p;
  };
  Station station(ses.client, "skull-1");
  station.run(path, steps);
  const auto& recs = station.records();
  ASSERT_GT(recs.size(), 200u) << ses.server.log();
  double deepest = 0.0;
  std::size_t with_planes = 0;
  for (const auto& r : recs) {
    EXPECT_FALSE(r.in_contact) << "seq " << r.seq << ": the brain was touched through the skull";
    with_planes += r.planes.empty() ? 0 : 1;
    deepest = std::max(deepest, max_penetration(r));
    for (const auto& q : r.planes) {
      EXPECT_NEAR(std::sqrt(q.normal[0] * q.normal[0] + q.normal[1] * q.normal[1] + q.normal[2] * q.normal[2]),
                  1.0, 1e-9);
      EXPECT_LE(r.planes.size(), 8u);
    }
  }
  EXPECT_GT(with_planes, 100u);
  EXPECT_GT(deepest, end_depth - 0.001);  // the device went end_depth past the outer table
  std::printf("skull: %zu ContactModels, %zu with planes, deepest raw penetration %.2f mm (device %.1f mm "
              "below the outer table; the brain at %.1f mm)\n",
              recs.size(), with_planes, 1e3 * deepest, 1e3 * end_depth, 1e3 * brain_depth);
}

TEST(service_rigid, ThroughTheOpeningUnblockedWithTheInProcessForces) {
  const st::Setup setup = skull_setup();
  st::Session ses(setup, "rigid_opening", 30);
  auto ref = setup.make_reference();
  ASSERT_TRUE(ses.wait_ready());
  const scene::RigidOpening& hole = skull_scene().rigid.front().openings.front();
  const mesh::Vec3 start = hole.center_m + 0.04 * hole.axis;
  auto path = [&](int k) {
    interaction::ToolPose p;
    p.tip_m = start - (0.0005 * k) * hole.axis;
    p.axis = hole.axis;
    return p;
  };
  // In along the axis at 0.5 m/s until 4 mm past the first touch of the brain (in-process).
  int first_touch = -1;
  {
    auto probe = setup.make_reference();
    std::vector<interaction::ToolPose> poses(1);
    std::vector<interaction::ToolContact> contacts;
    interaction::StepStats stats;
    for (int k = 0; k < 200 && first_touch < 0; ++k) {
      poses[0] = path(k);
      probe->step(poses, contacts, stats);
      if (contacts[0].in_contact) first_touch = k;
    }
  }
  ASSERT_GT(first_touch, 0) << "the brain is not within 100 mm along the opening's axis";
  const int steps = first_touch + 8;
  Station station(ses.client, "hole-1");
  station.run(path, steps);
  std::vector<interaction::ToolPose> poses(1);
  std::vector<interaction::ToolContact> contacts;
  interaction::StepStats stats;
  std::size_t compared = 0, in_contact = 0;
  for (const auto& r : station.records()) {
    EXPECT_EQ(max_penetration(r), 0.0) << "seq " << r.seq;
    poses[0] = station.sent(r.seq);
    ref->step(poses, contacts, stats);
    const auto& c = contacts[0];
    ASSERT_EQ(r.in_contact, c.in_contact) << "seq " << r.seq << " tip " << poses[0].tip_m.transpose()
                                          << " server force " << r.f0[0] << " " << r.f0[1] << " " << r.f0[2]
                                          << " planes " << r.planes.size();
    ++compared;
    if (!c.in_contact) continue;
    ++in_contact;
    EXPECT_EQ(r.mesh, "brain");
    const interaction::Vec3 f(r.f0[0], r.f0[1], r.f0[2]);
    EXPECT_LE((f - c.force_n).norm(), 1e-9 * c.force_n.norm()) << "seq " << r.seq;
    if (::testing::Test::HasFailure()) break;
  }
  EXPECT_GT(compared, 200u);
  EXPECT_GT(in_contact, 50u) << "the probe should reach the cerebellum";
  std::printf("opening: %zu ContactModels compared, %zu in contact (brain touched %.1f mm along the axis "
              "from 40 mm outside the opening's centre)\n",
              compared, in_contact, 0.5 * first_touch);
}

// Effects: without rigid meshes nothing is built and no plane is sent.
TEST(service_rigid, SceneWithoutRigidMeshesBuildsNoObstacle) {
  st::Setup setup;
  setup.exe = nt::bin_dir() / "neurosim-server";
  setup.scene = nt::source_dir() / "scenes/cube_cylinder.scene";
  setup.startup_timeout_s = 240;
  st::Session ses(setup, "rigid_none", 30);
  ASSERT_TRUE(ses.wait_ready());
  EXPECT_EQ(ses.server.log().find("rigid obstacles"), std::string::npos) << ses.server.log();
  Station station(ses.client, "none-1");
  station.run([&](int) {
    interaction::ToolPose p;
    p.tip_m = interaction::Vec3(setup.face_x_m + 0.001, setup.centre_y_m, setup.centre_z_m);
    return p;
  }, 50);
  ASSERT_GT(station.records().size(), 50u);
  for (const auto& r : station.records()) EXPECT_TRUE(r.planes.empty());
}

// The demo's surgical approach end to end: the real server on brain_skull.scene and the real
// neurosim-haptic running script:approach at the craniotomy (--at-opening), both child
// processes on loopback with a topic prefix of their own. From the station's trace: while it
// slides along the bone the wall holds it (rigid contact, a wall force, the proxy outside the
// bone and a tip radius off it, no tissue force); through the opening it presses the
// cerebellum (tissue contact, no wall); the force never steps by more than the loop's bound and
// stays finite and clamped (the step per nominal loop period: a late tick may move further).
TEST(service_rigid, ApproachStationSlidesOnTheBoneThenPressesTheCerebellumThroughTheOpening) {
  namespace fs = std::filesystem;
  const fs::path dir = nt::temp_dir("rigid_approach");
  const std::string prefix = "approach" + std::to_string(::getpid()) + "_";
  const fs::path scene = nt::source_dir() / "scenes/brain_skull.scene";
  st::ChildProcess server(nt::bin_dir() / "neurosim-server",
                          {"--scene", scene.string(), "--topic-prefix", prefix, "--duration", "120",
                           "--cache-dir", nt::shared_cache_dir().string()},
                          dir / "server.log");
  st::ChildProcess station(nt::bin_dir() / "neurosim-haptic",
                           {"--station", "approach", "--device", "script:approach", "--at-opening",
                            "--scene", scene.string(), "--duration", "10.5", "--no-rt",
                            "--wait-server", "120", "--topic-prefix", prefix, "--trace",
                            (dir / "trace.csv").string()},
                           dir / "haptic.log");
  ASSERT_EQ(station.wait(240), 0) << station.log() << "\n" << server.log();
  server.signal_and_wait(SIGTERM, 10);

  struct Tick {
    double t, clock, x[3], f[3], proxy[3], wall[3];
    bool tissue, rigid;
  };
  std::vector<Tick> ticks;
  {
    std::ifstream in(dir / "trace.csv");
    std::string line;
    std::getline(in, line);
    ASSERT_EQ(line.rfind("t_s,x_m,y_m,z_m,fx_n,fy_n,fz_n,model_age_ms,gain,in_contact,", 0), 0u)
        << line;
    ASSERT_NE(line.find(",clock_s"), std::string::npos) << line;
    while (std::getline(in, line)) {
      std::vector<double> c;
      std::stringstream ss(line);
      std::string cell;
      while (std::getline(ss, cell, ',')) c.push_back(std::stod(cell));
      ASSERT_EQ(c.size(), 19u) << line;
      Tick k{};
      k.t = c[0];
      k.clock = c[18];
      for (int i = 0; i < 3; ++i) {
        k.x[i] = c[1 + i];
        k.f[i] = c[4 + i];
        k.proxy[i] = c[12 + i];
        k.wall[i] = c[15 + i];
      }
      k.tissue = c[9] > 0;
      k.rigid = c[11] > 0;
      ticks.push_back(k);
    }
  }
  ASSERT_GT(ticks.size(), 10000u);
  const auto obstacle = interaction::RigidObstacle::build(skull_scene().rigid);
  const double r_tip = skull_scene().tools.front().tip_radius_m;
  const double max_force = skull_scene().haptics.max_force_n;
  auto norm = [](const double v[3]) { return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]); };
  int slide = 0, slide_rigid = 0, slide_tissue = 0, press = 0, press_tissue = 0, press_rigid = 0;
  int checked = 0;
  double slide_wall_n = 0, press_tissue_n = 0, max_step_n = 0, min_bone_gap_m = 1;
  for (std::size_t i = 0; i < ticks.size(); ++i) {
    const Tick& k = ticks[i];
    ASSERT_TRUE(std::isfinite(norm(k.f)) && std::isfinite(norm(k.wall))) << "t " << k.t;
    EXPECT_LE(norm(k.f), max_force + 1e-9) << "t " << k.t;
    if (i > 0) {
      const double d[3] = {k.f[0] - ticks[i - 1].f[0], k.f[1] - ticks[i - 1].f[1],
                           k.f[2] - ticks[i - 1].f[2]};
      // The bound is a rate per nominal period: a tick late by n periods (a busy machine) may
      // move n times as far (ForceModel, as the fault harness measures it), by the loop's clock
      // (clock_s, to the ns; t_s is the nominal k T) as ForceModel reads it: at most 0.1 s.
      const double periods =
          std::max(1.0, std::min(k.clock - ticks[i - 1].clock, 0.1) /
                            haptic::ForceModelConfig{}.period_s);
      max_step_n = std::max(max_step_n, norm(d) / periods);
    }
    if (k.t > 2.2 && k.t < 4.5) {  // on the bone, sliding to the rim
      ++slide;
      slide_rigid += k.rigid;
      slide_tissue += k.tissue;
      if (k.rigid) slide_wall_n = std::max(slide_wall_n, norm(k.wall));
    }
    if (k.t > 7.0 && k.t < 8.7) {  // on the cerebellum
      ++press;
      press_tissue += k.tissue;
      press_rigid += k.rigid;
      if (k.tissue) press_tissue_n = std::max(press_tissue_n, norm(k.f));
    }
    if (k.rigid && i % 25 == 0) {  // the proxy: outside the bone, the tip sphere clear of it
      const mesh::Vec3 p(k.proxy[0], k.proxy[1], k.proxy[2]);
      EXPECT_FALSE(obstacle->inside(p)) << "proxy inside the bone at t " << k.t;
      min_bone_gap_m = std::min(min_bone_gap_m, obstacle->closest(p).distance_m);
      ++checked;
    }
  }
  std::printf("approach: slide %d ticks (%d on the bone, %d tissue), wall force up to %.3f N, "
              "proxy >= %.2f mm from the bone (%d checked); press %d ticks (%d tissue, %d bone), "
              "tissue force up to %.3f N; max force step %.4f N per period\n",
              slide, slide_rigid, slide_tissue, slide_wall_n, min_bone_gap_m * 1e3, checked, press,
              press_tissue, press_rigid, press_tissue_n, max_step_n);
  EXPECT_GT(slide_rigid, 0.9 * slide) << "the bone holds the tool while it slides";
  EXPECT_EQ(slide_tissue, 0) << "no tissue behind the bone is touched";
  EXPECT_GT(slide_wall_n, 0.3);
  EXPECT_GT(checked, 50);
  EXPECT_GT(min_bone_gap_m, r_tip - 0.3e-3) << "the tip sphere stays off the bone";
  EXPECT_GT(press_tissue, 0.9 * press) << "through the opening the cerebellum is pressed";
  EXPECT_EQ(press_rigid, 0) << "inside the opening nothing of the bone is touched";
  EXPECT_GT(press_tissue_n, 0.03);
  EXPECT_LT(press_tissue_n, 1.0);
  EXPECT_LE(max_step_n, haptic::ForceModelConfig{}.max_force_step_n + 1e-9);
  fs::remove_all(dir);
}
