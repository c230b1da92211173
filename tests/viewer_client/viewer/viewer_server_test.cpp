// The viewer against the real neurosim-server on the brain/artery scene:
//  - a render with the tool pushing the brain differs from the undeformed render around the
//    pushed spot and nowhere else beyond noise (in-process pipeline, both modes);
//  - neurosim-viewer joining late still gets the topology and the deformation;
//  - neurosim-viewer survives the server being killed and started again;
//  - the server's tier and its equilibrium update rate (SimStatus) reach the viewer's log and
//    --summary (the real server code with the test-only fake physics and --tier nonlinear, which
//    reports a non-zero rate: the real physics runs only LINEAR for now).
// VTK renders through X here: each test runs its own Xvfb (-displayfd picks a free display).
// Every server has its own --topic-prefix, so parallel ctest runs do not see each other.
#include "idl/wire/dds.hpp"
#include "viewer_client/viewer/dds_client.hpp"
#include "viewer_client/viewer/image_io.hpp"
#include "viewer_client/viewer/pipeline.hpp"
#include "viewer_test_util.hpp"

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include <atomic>
#include <cmath>
#include <thread>

namespace nv = neurosim::viewer;
namespace nt = neurosim::testing;
namespace wire = neurosim::wire;
namespace fs = std::filesystem;

namespace {

constexpr double kTipRadiusM = 0.002;  // the scene's probe
constexpr double kPressDepthM = 0.004;

std::string unique_prefix(const std::string& tag) {
  return "vt" + tag + std::to_string(getpid()) + "_";
}

// Waits (polling) until the client has both meshes of the scene.
bool wait_for_topology(nv::DdsClient& client, nv::ViewerState& state, double timeout_s) {
  const auto t0 = std::chrono::steady_clock::now();
  while (nt::seconds_since(t0) < timeout_s) {
    client.wait(0.1);
    client.poll(state);
    if (state.mesh("brain") != nullptr && state.mesh("artery") != nullptr) return true;
  }
  return false;
}

// A station pressing the brain at `p` along -n: approaches from 8 mm outside in 1.5 s, then holds
// at kPressDepthM (sphere surface below the rest surface), writing at 500 Hz until stopped.
class PressingStation {
 public:
  PressingStation(const std::string& prefix, const nt::PressPoint& p)
      : pp_(), topic_(pp_, wire::topic_name<neurosim_ToolState>(prefix)),
        writer_(pp_, topic_, "test-station") {
    thread_ = std::thread([this, p] { run(p); });
  }
  ~PressingStation() {
    stop_ = true;
    thread_.join();
  }

 private:
  void run(const nt::PressPoint& p) {
    wire::Sample<neurosim_ToolState> s;
    wire::set_string(s->station_id, "test-station");
    wire::set_string(s->tool_id, "probe");
    const Eigen::Quaterniond q =
        Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), p.normal);
    s->orientation[0] = q.w();
    s->orientation[1] = q.x();
    s->orientation[2] = q.y();
    s->orientation[3] = q.z();
    const Eigen::Vector3d start = p.point_m + (kTipRadiusM + 0.008) * p.normal;
    const Eigen::Vector3d end = p.point_m + (kTipRadiusM - kPressDepthM) * p.normal;
    const auto t0 = std::chrono::steady_clock::now();
    std::uint64_t seq = 0;
    while (!stop_) {
      const double a = std::min(nt::seconds_since(t0) / 1.5, 1.0);
      const Eigen::Vector3d x = start + a * (end - start);
      for (int i = 0; i < 3; ++i) {
        s->position_m[i] = x[i];
        s->velocity_m_per_s[i] = 0;
      }
      s->sequence_number = ++seq;
      s->source_time_ns = dds_time();
      writer_.write(*s);
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  wire::Participant pp_;
  wire::Topic<neurosim_ToolState> topic_;
  wire::Writer<neurosim_ToolState> writer_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

double json_number(const std::string& json, const std::string& key) {
  const auto p = json.find("\"" + key + "\":");
  if (p == std::string::npos) return std::nan("");
  return std::stod(json.substr(p + key.size() + 3));
}

struct DiffStats {
  std::size_t inside = 0, outside = 0;  // pixels in / out of the mask
  std::size_t changed_inside = 0, changed_outside = 0;
};

// A pixel of a counts as changed when no pixel of b within `shift` pixels matches it to
// `threshold` (max over RGB): sub-pixel motion of far-away edges (the soft brain shifts by a
// fraction of a millimetre as a whole) is noise, a visible dent is not.
std::vector<std::uint8_t> changed_pixels(const std::vector<std::uint8_t>& a,
                                         const std::vector<std::uint8_t>& b, int w, int h,
                                         int threshold, int shift) {
  std::vector<std::uint8_t> out(static_cast<std::size_t>(w) * static_cast<std::size_t>(h), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const std::size_t i =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      int best = 256;
      for (int dy = -shift; dy <= shift && best > threshold; ++dy)
        for (int dx = -shift; dx <= shift && best > threshold; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          const std::size_t j = static_cast<std::size_t>(yy) * static_cast<std::size_t>(w) +
                                static_cast<std::size_t>(xx);
          int m = 0;
          for (std::size_t c = 0; c < 3; ++c)
            m = std::max(m, std::abs(int(a[3 * i + c]) - int(b[3 * j + c])));
          best = std::min(best, m);
        }
      out[i] = best > threshold ? 1 : 0;
    }
  return out;
}

DiffStats compare(const std::vector<std::uint8_t>& changed, const std::vector<std::uint8_t>& mask) {
  DiffStats d;
  for (std::size_t i = 0; i < mask.size(); ++i) {
    if (mask[i]) {
      ++d.inside;
      d.changed_inside += changed[i];
    } else {
      ++d.outside;
      d.changed_outside += changed[i];
    }
  }
  return d;
}

}  // namespace

// Deformed vs undeformed render of the same moment (same tool, same slices): the difference is
// confined to a ball around the pushed spot.
TEST(ViewerServer, DeformedRenderDiffersOnlyWhereTheToolPushes) {
  nt::Xvfb x;
  const std::string prefix = unique_prefix("r");
  const fs::path dir = nt::temp_dir("viewer_render");
  nt::Child server(nt::server_args(prefix, 300), dir / "server.log");

  nv::DdsClient client({-1, prefix});
  nv::ViewerState state;
  ASSERT_TRUE(wait_for_topology(client, state, 120)) << server.log();
  const nt::PressPoint press = nt::press_point(*state.mesh("brain"));
  PressingStation station(prefix, press);

  // Wait for the press to settle: the newest frames show > 2 mm and stop growing, and the
  // server's steps no longer wait for compliance columns (SimStatus.columns_not_ready, summed
  // over steps, unchanged for 2 s). Under load the column worker (nice 10: it yields to every
  // busy process) lands the press's reach block by block over tens of seconds, each block moving
  // the press (its rows take the fallback until their columns are ready): the frames alone can
  // hold still for 2 s at a press still growing. And the frames must come from a step after
  // the last column landed (Deformation.server_step at least SimStatus.steps of the first status
  // with the final count): under load the field thread (normal priority) can fall seconds behind
  // the step, and its frames then hold still at an older, smaller press (a fresh machine's CI
  // run rendered a 3.28 mm press where the settled one is 3.68 mm).
  wire::Participant status_pp;
  wire::Topic<neurosim_SimStatus> status_topic(status_pp,
                                               wire::topic_name<neurosim_SimStatus>(prefix));
  wire::Reader<neurosim_SimStatus> status_reader(status_pp, status_topic);
  const auto t0 = std::chrono::steady_clock::now();
  auto not_ready_since = t0;
  std::uint64_t not_ready = 0, steps_at_final_count = 0;
  bool status_seen = false;
  double last = -1;
  int stable = 0;
  while (nt::seconds_since(t0) < 180) {
    client.wait(0.1);
    client.poll(state);
    for (const auto& rx : status_reader.take()) {
      if (!rx.valid()) continue;
      if (!status_seen || rx.data.columns_not_ready != not_ready) {
        not_ready_since = std::chrono::steady_clock::now();
        steps_at_final_count = rx.data.steps;
      }
      status_seen = true;
      not_ready = rx.data.columns_not_ready;
    }
    const double m = state.max_displacement_m();
    const nv::MeshState* brain = state.mesh("brain");
    const bool after_columns = status_seen && brain != nullptr &&
                               brain->server_step >= steps_at_final_count;
    stable = (m > 0.002 && after_columns && std::abs(m - last) < 1e-5) ? stable + 1 : 0;
    last = m;
    if (stable >= 20 && nt::seconds_since(not_ready_since) >= 2.0) break;
  }
  std::printf("settled after %.1f s: columns not ready %llu (summed over steps), the last of them "
              "counted by step %llu, frames of step %llu\n",
              nt::seconds_since(t0), static_cast<unsigned long long>(not_ready),
              static_cast<unsigned long long>(steps_at_final_count),
              static_cast<unsigned long long>(state.mesh("brain")->server_step));
  ASSERT_TRUE(status_seen) << "no SimStatus arrived: " << server.log();
  ASSERT_GE(nt::seconds_since(not_ready_since), 2.0)
      << "the server's steps still wait for compliance columns: " << server.log();
  ASSERT_GT(state.max_displacement_m(), 0.002) << "no deformation arrived: " << server.log();
  const nv::ToolView* tool = state.primary_tool();
  ASSERT_NE(tool, nullptr);
  EXPECT_TRUE(tool->in_contact);
  EXPECT_GT(tool->force_n.norm(), 0.0);

  // The same moment without the displacements.
  nv::ViewerState deformed = state;
  nv::ViewerState undeformed = state;
  for (const auto& m : undeformed.meshes())
    undeformed.set_displacements(m.id, std::vector<float>(m.u_m.size(), 0.0F));

  // How far the tissue moves away from the pushed spot (the soft brain also shifts a little as
  // a whole on its fixed base): the largest |u| beyond kMaskRadiusM.
  constexpr double kMaskRadiusM = 0.03;
  double far_u = 0;
  for (const auto& m : deformed.meshes())
    for (std::size_t i = 0; i < m.rest_m.size(); ++i)
      if ((m.rest_m[i] - press.point_m).norm() > kMaskRadiusM)
        far_u = std::max(
            far_u,
            double(Eigen::Vector3f(m.u_m[3 * i], m.u_m[3 * i + 1], m.u_m[3 * i + 2]).norm()));
  std::printf("max |u| %.2f mm, |F| %.3f N, max |u| beyond %.0f mm of the spot: %.2f mm\n",
              deformed.max_displacement_m() * 1e3, tool->force_n.norm(), kMaskRadiusM * 1e3,
              far_u * 1e3);

  for (const nv::Mode mode : {nv::Mode::Navigation, nv::Mode::Observe}) {
    SCOPED_TRACE(nv::to_string(mode));
    nv::PipelineOptions po;
    po.render.mode = mode;
    po.render.width = 640;
    po.render.height = 480;
    po.render.overlay = false;
    std::vector<std::string> warnings;
    nv::Pipeline pipe(po, [&](const std::string& w) { warnings.push_back(w); });
    pipe.frame(deformed, "");
    ASSERT_TRUE(pipe.has_image()) << (warnings.empty() ? "" : warnings.front());
    const auto a = pipe.renderer().capture();
    pipe.renderer().write_png(
        (dir / (std::string(nv::to_string(mode)) + "_deformed.png")).string());
    pipe.frame(undeformed, "");
    const auto b = pipe.renderer().capture();
    pipe.renderer().write_png(
        (dir / (std::string(nv::to_string(mode)) + "_undeformed.png")).string());
    // Again deformed: rendering is repeatable (the noise floor is zero here).
    pipe.frame(deformed, "");
    const auto a2 = pipe.renderer().capture();
    ASSERT_EQ(a.size(), b.size());
    const auto mask = pipe.renderer().mask_around(press.point_m, kMaskRadiusM);
    const int w = pipe.renderer().width(), h = pipe.renderer().height();
    // Navigation's 2D views magnify (~1.6 px/mm): tolerate 1 px shifts of far edges. The
    // observe view is small (whole brain in view) and needs no tolerance.
    const int shift = mode == nv::Mode::Navigation ? 1 : 0;
    const auto changed = changed_pixels(a, b, w, h, 24, shift);
    const DiffStats d = compare(changed, mask);
    const DiffStats noise = compare(changed_pixels(a, a2, w, h, 0, 0), mask);
    std::printf("%s: mask %zu px; changed inside %zu, outside %zu of %zu; repeat changed %zu\n",
                nv::to_string(mode), d.inside, d.changed_inside, d.changed_outside, d.outside,
                noise.changed_inside + noise.changed_outside);
    {
      // Difference picture for a reader: changed pixels red, the mask dimmed blue.
      std::vector<std::uint8_t> pic(a.size());
      for (std::size_t i = 0; i < mask.size(); ++i) {
        const std::uint8_t g = static_cast<std::uint8_t>(a[3 * i] / 3);
        pic[3 * i] = changed[i] ? 255 : g;
        pic[3 * i + 1] = g;
        pic[3 * i + 2] = mask[i] ? 120 : g;
      }
      nv::write_png_rgb((dir / (std::string(nv::to_string(mode)) + "_diff.png")).string(), w, h,
                        pic);
    }
    EXPECT_TRUE(warnings.empty()) << warnings.front();
    EXPECT_LT(d.inside, mask.size() / 3) << "mask is not local";
    EXPECT_GT(d.changed_inside, 50u) << "the press does not show";
    EXPECT_LE(d.changed_outside, d.outside / 1000) << "changes away from the pushed spot";
    EXPECT_EQ(noise.changed_inside + noise.changed_outside, 0u);
  }
  if (!HasFailure() && std::getenv("NEUROSIM_KEEP_TEST_OUTPUT") == nullptr)
    fs::remove_all(dir);
  else
    std::printf("renders and differences kept in %s\n", dir.c_str());
}

// A viewer started while a station already presses gets the topology and the deformation.
TEST(ViewerServer, LateJoinerGetsTopologyAndDeformation) {
  nt::Xvfb x;
  const std::string prefix = unique_prefix("l");
  const fs::path dir = nt::temp_dir("viewer_late");
  nt::Child server(nt::server_args(prefix, 150), dir / "server.log");
  {
    nv::DdsClient client({-1, prefix});
    nv::ViewerState state;
    ASSERT_TRUE(wait_for_topology(client, state, 120)) << server.log();
    const nt::PressPoint press = nt::press_point(*state.mesh("brain"));
    PressingStation station(prefix, press);
    // Pressing before the viewer exists: wait until the press shows (> 2 mm) in this client's
    // frames, by the deformation, never by a fixed time (the column worker's first reach of the
    // bundled brain takes longer under load; its rows are out until then).
    const auto t0 = std::chrono::steady_clock::now();
    while (nt::seconds_since(t0) < 120 && state.max_displacement_m() <= 0.002) {
      client.wait(0.1);
      client.poll(state);
    }
    ASSERT_GT(state.max_displacement_m(), 0.002) << "no deformation arrived: " << server.log();

    nt::Child viewer({(nt::bin_dir() / "neurosim-viewer").string(), "--mode", "navigation",
                      "--headless", "--frames", "6", "--fps", "3", "--out",
                      (dir / "frames").string(), "--size", "480x360", "--topic-prefix", prefix,
                      "--wait-server", "60", "--summary", (dir / "summary.json").string()},
                     dir / "viewer.log");
    ASSERT_TRUE(viewer.wait(90)) << viewer.log();
    ASSERT_TRUE(WIFEXITED(viewer.status()) && WEXITSTATUS(viewer.status()) == 0) << viewer.log();
  }
  const std::string summary = nt::slurp(dir / "summary.json");
  EXPECT_EQ(json_number(summary, "meshes"), 2) << summary;
  EXPECT_GE(json_number(summary, "topologies"), 2) << summary;
  EXPECT_GE(json_number(summary, "deformations"), 1) << summary;
  EXPECT_GT(json_number(summary, "max_displacement_m"), 0.002) << summary;
  EXPECT_EQ(json_number(summary, "malformed"), 0) << summary;
  // The brain scene runs LINEAR: no equilibrium updates.
  EXPECT_NE(summary.find("\"server_tier\": \"LINEAR\""), std::string::npos) << summary;
  EXPECT_EQ(json_number(summary, "tier_update_rate_hz"), 0.0) << summary;
  EXPECT_TRUE(fs::exists(dir / "frames/frame_0000.png"));
  EXPECT_TRUE(fs::exists(dir / "frames/frame_0005.png"));
  fs::remove_all(dir);
}

// The server dies (SIGKILL) and a new one starts: the viewer keeps rendering the last state,
// says it waits, and picks up the new server's topology.
TEST(ViewerServer, SurvivesServerRestart) {
  nt::Xvfb x;
  const std::string prefix = unique_prefix("s");
  const fs::path dir = nt::temp_dir("viewer_restart");
  auto server = std::make_unique<nt::Child>(nt::server_args(prefix, 150), dir / "server1.log");
  nt::Child viewer({(nt::bin_dir() / "neurosim-viewer").string(), "--mode", "navigation",
                    "--headless", "--duration", "200", "--fps", "4", "--out",
                    (dir / "frames").string(), "--size", "320x240", "--topic-prefix", prefix,
                    "--wait-server", "120", "--summary", (dir / "summary.json").string()},
                   dir / "viewer.log");
  ASSERT_TRUE(viewer.wait_for_log("topology:", 120)) << viewer.log() << server->log();
  ASSERT_TRUE(viewer.wait_for_log("server seen", 30)) << viewer.log();

  server->kill(SIGKILL);
  ASSERT_TRUE(viewer.wait_for_log("server lost", 10)) << viewer.log();
  // Still rendering while the server is away.
  auto frames = [&] {
    std::size_t n = 0;
    for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir / "frames")) ++n;
    return n;
  };
  const std::size_t before = frames();
  std::this_thread::sleep_for(std::chrono::seconds(2));
  EXPECT_GT(frames(), before) << "the viewer stopped rendering without a server";
  ASSERT_TRUE(viewer.running()) << viewer.log();

  server = std::make_unique<nt::Child>(nt::server_args(prefix, 150), dir / "server2.log");
  ASSERT_TRUE(viewer.wait_for_log("server back", 120)) << viewer.log() << server->log();
  ASSERT_TRUE(viewer.wait_for_log("topology:", 30, 2)) << viewer.log();
  const int status = viewer.kill(SIGINT);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << viewer.log();
  const std::string summary = nt::slurp(dir / "summary.json");
  EXPECT_GE(json_number(summary, "server_lost"), 1) << summary;
  EXPECT_GE(json_number(summary, "server_seen"), 2) << summary;
  EXPECT_GE(json_number(summary, "topologies"), 4) << summary;
  fs::remove_all(dir);
}

// SimStatus.tier and tier_update_rate_hz through DdsClient into the state, the viewer's log and
// its --summary: the fake-physics server (tests/server/service) with --tier nonlinear reports
// FakeSimulation::kTierUpdateRateHz (12.5 Hz) once a station made it step.
TEST(ViewerServer, ShowsTheServersTierAndEquilibriumRate) {
  nt::Xvfb x;
  const std::string prefix = unique_prefix("t");
  const fs::path dir = nt::temp_dir("viewer_tier");
  nt::Child server({(nt::bin_dir() / "service_test_fake_server").string(), "--scene",
                    (nt::source_dir() / "tests/server/service/data/fake_box.scene").string(),
                    "--tier", "nonlinear", "--topic-prefix", prefix, "--duration", "60"},
                   dir / "server.log");
  // The fake box's +x face (x = 0.1 m) at the centre of its y/z extent.
  PressingStation station(prefix, nt::PressPoint{Eigen::Vector3d(0.1, 0.05, 0.05),
                                                 Eigen::Vector3d::UnitX()});
  {
    nv::DdsClient client({-1, prefix});
    nv::ViewerState state;
    const auto t0 = std::chrono::steady_clock::now();
    while (nt::seconds_since(t0) < 30 && !(state.server_status().received &&
                                           state.server_status().tier_update_rate_hz > 0)) {
      client.wait(0.1);
      client.poll(state);
    }
    ASSERT_TRUE(state.server_status().received) << "no SimStatus\n" << server.log();
    EXPECT_EQ(state.server_status().tier, "NONLINEAR") << server.log();
    EXPECT_EQ(state.server_status().tier_update_rate_hz, 12.5) << server.log();
  }
  nt::Child viewer({(nt::bin_dir() / "neurosim-viewer").string(), "--mode", "navigation",
                    "--headless", "--frames", "3", "--fps", "4", "--out",
                    (dir / "frames").string(), "--size", "320x240", "--topic-prefix", prefix,
                    "--wait-server", "30", "--summary", (dir / "summary.json").string()},
                   dir / "viewer.log");
  ASSERT_TRUE(viewer.wait(60)) << viewer.log();
  ASSERT_TRUE(WIFEXITED(viewer.status()) && WEXITSTATUS(viewer.status()) == 0) << viewer.log();
  const std::string log = viewer.log();
  EXPECT_NE(log.find("runs tier NONLINEAR"), std::string::npos) << log;
  EXPECT_NE(log.find("last SimStatus: tier NONLINEAR, equilibrium 1"), std::string::npos) << log;
  const std::string summary = nt::slurp(dir / "summary.json");
  EXPECT_NE(summary.find("\"server_tier\": \"NONLINEAR\""), std::string::npos) << summary;
  EXPECT_EQ(json_number(summary, "tier_update_rate_hz"), 12.5) << summary;
  EXPECT_GE(json_number(summary, "statuses"), 1) << summary;
  fs::remove_all(dir);
}
