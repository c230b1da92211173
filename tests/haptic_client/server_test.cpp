// The haptic client against the real neurosim-server: killing the server
// mid-contact fades the force to zero in time; replaying one recording twice against fresh
// servers gives identical ContactModel sequences.
//
// The server is NEUROSIM_SERVER (environment) or <bin>/neurosim-server; the test is skipped when
// neither exists, or when the server exits by itself before answering (e.g. built without
// physics) — the reason is printed. Each server runs with its own --topic-prefix.
#include "common/clock.hpp"
#include "haptic_client/dds_link.hpp"
#include "haptic_client/loop.hpp"
#include "idl/wire/dds.hpp"
#include "idl/wire/recording_io.hpp"
#include "test_support.hpp"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <mutex>
#include <thread>

extern char** environ;
namespace nh = neurosim::haptic;
namespace wire = neurosim::wire;
namespace fs = std::filesystem;
using Eigen::Vector3d;

namespace {

using neurosim::common::seconds_since;

fs::path server_binary() {
  if (const char* e = std::getenv("NEUROSIM_SERVER"); e != nullptr && *e != '\0') return e;
  return neurosim::testing::bin_dir() / "neurosim-server";
}

fs::path cube_scene() { return neurosim::testing::source_dir() / "scenes/cube_cylinder.scene"; }

// The cube's right face (x = 0.1 m), outward normal +x: where the bundled script recordings press.
const Vector3d kFaceOrigin(0.1, 0.05, 0.05);
const Vector3d kFaceNormal(1, 0, 0);

class ServerProcess {
 public:
  ServerProcess(const std::string& prefix, const fs::path& log) : prefix_(prefix) {
    const std::string bin = server_binary().string();
    std::vector<std::string> args{
        bin, "--scene", cube_scene().string(), "--topic-prefix", prefix, "--duration", "240"};
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    const int rc = posix_spawn(&pid_, bin.c_str(), &fa, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("cannot start " + bin);
  }
  ~ServerProcess() { kill(SIGKILL); }
  void kill(int sig) {
    if (pid_ <= 0) return;
    ::kill(pid_, sig);
    waitpid(pid_, nullptr, 0);
    pid_ = 0;
  }
  // True (and the exit status) if the process already ended by itself.
  bool exited(int& status) {
    if (pid_ <= 0) return false;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = 0;
      return true;
    }
    return false;
  }
  nh::DdsLinkOptions link_options(const std::string& station) const {
    nh::DdsLinkOptions o;
    o.station_id = station;
    o.tool_id = "probe";
    o.topic_prefix = prefix_;
    return o;
  }

 private:
  std::string prefix_;
  pid_t pid_ = 0;
};

std::string read_file(const fs::path& p) {
  std::FILE* f = std::fopen(p.c_str(), "r");
  if (!f) return {};
  std::string s;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) s.append(buf, n);
  std::fclose(f);
  return s;
}

// Waits for the server's first ContactModel; skips the test if the server ended by itself.
#define WAIT_FOR_SERVER_OR_SKIP(server, link, log)                                          \
  do {                                                                                      \
    const auto t0_ = std::chrono::steady_clock::now();                                      \
    bool up_ = false;                                                                       \
    while (seconds_since(t0_) < 180) {                                                      \
      int st_ = 0;                                                                          \
      if ((server).exited(st_))                                                             \
        GTEST_SKIP() << "neurosim-server ended before answering (status " << st_            \
                     << "): " << read_file(log);                                            \
      if ((link).wait_for_server(0.5)) {                                                    \
        up_ = true;                                                                         \
        break;                                                                              \
      }                                                                                     \
    }                                                                                       \
    ASSERT_TRUE(up_) << "neurosim-server did not come up within 180 s: " << read_file(log); \
  } while (0)

struct ModelRecord {
  Vector3d x0, f0, normal;
  double k[9];
  bool in_contact;
  bool operator==(const ModelRecord& o) const {
    for (int i = 0; i < 9; ++i)
      if (k[i] != o.k[i]) return false;
    return x0 == o.x0 && f0 == o.f0 && normal == o.normal && in_contact == o.in_contact;
  }
};

// Replays `rec` against a fresh server; returns the ContactModels seen, by tool sequence.
std::map<std::uint64_t, ModelRecord> replay_against_fresh_server(const fs::path& rec,
                                                                 const std::string& prefix,
                                                                 const fs::path& log,
                                                                 bool& skipped) {
  std::map<std::uint64_t, ModelRecord> seen;
  skipped = true;
  ServerProcess server(prefix, log);
  // A second reader (besides the client's) collecting every ContactModel.
  wire::Participant pp;
  wire::Topic<neurosim_ContactModel> topic(pp, wire::topic_name<neurosim_ContactModel>(prefix));
  // Keep-all: a starved collector thread must not lose models to keep-last-1 overwriting.
  wire::Qos qos = wire::reader_qos(wire::Profile::ContactModel);
  dds_qset_history(qos.get(), DDS_HISTORY_KEEP_ALL, 0);
  wire::Reader<neurosim_ContactModel> reader(pp, topic, qos, wire::ReaderOptions{256});
  nh::DdsLink link(server.link_options("replay"));
  {
    const auto t0 = std::chrono::steady_clock::now();
    bool up = false;
    while (seconds_since(t0) < 180) {
      int st = 0;
      if (server.exited(st)) {
        std::printf("neurosim-server ended before answering (status %d): %s\n", st,
                    read_file(log).c_str());
        return seen;
      }
      if (link.wait_for_server(0.5)) {
        up = true;
        break;
      }
    }
    if (!up) return seen;
  }
  skipped = false;
  std::atomic<bool> stop{false};
  std::mutex mu;
  std::thread collector([&] {
    wire::Waitset ws(pp);
    ws.attach_data(reader, 1);
    while (!stop) {
      ws.wait(DDS_MSECS(5));
      for (const auto& rx : reader.take()) {
        if (!rx.valid() || rx.key() != "replay") continue;
        const auto& c = rx.data;
        ModelRecord m;
        for (int i = 0; i < 3; ++i) {
          m.x0[i] = c.x0_position_m[i];
          m.f0[i] = c.f0_n[i];
          m.normal[i] = c.normal[i];
        }
        for (int i = 0; i < 9; ++i) m.k[i] = c.stiffness_n_per_m[i];
        m.in_contact = c.in_contact;
        std::lock_guard<std::mutex> lock(mu);
        seen.emplace(c.tool_sequence, m);
      }
    }
  });
  nh::ReplayDevice dev(rec.string());
  nh::LoopConfig cfg;
  cfg.realtime_priority = false;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  loop.run_realtime(30.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  stop = true;
  collector.join();
  server.kill(SIGTERM);
  return seen;
}

}  // namespace

TEST(haptic_server, KillingServerMidContactFadesForceToZeroInTime) {
  if (!fs::exists(server_binary())) GTEST_SKIP() << "no neurosim-server at " << server_binary();
  const fs::path dir = neurosim::testing::temp_dir("haptic_server_kill");
  const std::string prefix = "hkill" + std::to_string(::getpid()) + "_";
  ServerProcess server(prefix, dir / "server.log");
  nh::DdsLink link(server.link_options("kill"));
  WAIT_FOR_SERVER_OR_SKIP(server, link, dir / "server.log");

  // The tool is held 3 mm into the cube's right face.
  nh::ScriptDevice dev(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, -0.003)));
  nh::LoopConfig cfg;
  cfg.workspace_origin_m = kFaceOrigin;
  cfg.workspace_up = kFaceNormal;
  cfg.force.ramp_in_s = 0.2;
  cfg.realtime_priority = false;
  cfg.trace_capacity = 30000;
  nh::HapticLoop loop(cfg, dev, &link, nullptr);
  std::atomic<bool> stop{false};
  std::thread loop_thread([&] { loop.run_realtime(25.0, &stop); });
  const auto t0 = std::chrono::steady_clock::now();
  while (seconds_since(t0) < 10 && loop.last_force_norm() < 0.05)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // past the 0.2 s ramp-in
  const double f_contact = loop.last_force_norm();
  const auto kill_tick = static_cast<std::size_t>(loop.ticks());
  server.kill(SIGKILL);  // no goodbye: only the watchdog and liveliness can tell
  const auto killed = std::chrono::steady_clock::now();
  while (seconds_since(killed) < 5 && link.server_alive())
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  const double gone_after_s = seconds_since(killed);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  stop = true;
  loop_thread.join();
  ASSERT_GT(f_contact, 0.5) << "the tool never got a steady contact force from the server";
  EXPECT_FALSE(link.server_alive()) << "SimStatus liveliness did not report the killed server";
  EXPECT_EQ(loop.last_force_norm(), 0.0);

  const auto& tr = loop.trace();
  std::uint64_t last_seq = 0;
  std::int64_t last_ref = 0;
  // The first tick without force and the last one still pushing (the tick before it), in ms
  // after the newest model. A loop starved by the machine's load (no tick for 10-20 ms) puts its
  // last push anywhere before the watchdog and its first zero anywhere after it, so each bound is
  // on its own side: the force stays until the watchdog (the first zero at 50 ms or later) and
  // is gone soon after it (the last push before 70 ms). (The last push asserted >= 50 ms failed
  // once at 39 ms with a 2-core machine's load at 16.)
  double zero_ms = -1, push_ms = -1;
  for (std::size_t i = kill_tick > 200 ? kill_tick - 200 : 0; i < tr.size(); ++i) {
    if (tr[i].model_sequence > last_seq && tr[i].force_n.norm() > 0) {
      last_seq = tr[i].model_sequence;
      last_ref = tr[i].now_ns - static_cast<std::int64_t>(std::llround(tr[i].model_age_s * 1e9));
    }
    if (i > kill_tick && tr[i].force_n.norm() == 0) {
      zero_ms = 1e-6 * static_cast<double>(tr[i].now_ns - last_ref);
      push_ms = 1e-6 * static_cast<double>(tr[i - 1].now_ns - last_ref);
      break;
    }
  }
  std::printf(
      "contact force %.3f N; last force %.1f ms and first tick without it %.1f ms after the newest "
      "model; server seen gone after %.2f s\n",
      f_contact, push_ms, zero_ms, gone_after_s);
  EXPECT_GE(zero_ms, 50) << "kill -9 is only seen by the 50 ms watchdog (liveliness takes ~0.5 s)";
  EXPECT_GE(push_ms, 0) << "no tick pushed after the newest model";
  EXPECT_LT(push_ms, 50 + 20) << "no force 70 ms after the newest model";
  double max_step = 0;
  for (std::size_t i = 1; i < tr.size(); ++i) {
    // The bound is per nominal 1 ms period: a late tick may move as far as the ticks it replaced.
    const double periods =
        std::max(1.0, 1e-6 * static_cast<double>(tr[i].now_ns - tr[i - 1].now_ns));
    max_step = std::max(max_step, (tr[i].force_n - tr[i - 1].force_n).norm() / periods);
  }
  EXPECT_LE(max_step, cfg.force.max_force_step_n + 1e-12);
  fs::remove_all(dir);
}

TEST(haptic_server, ReplayingOneRecordingTwiceGivesIdenticalContactModels) {
  if (!fs::exists(server_binary())) GTEST_SKIP() << "no neurosim-server at " << server_binary();
  const fs::path dir = neurosim::testing::temp_dir("haptic_server_replay");
  const fs::path rec = neurosim::testing::source_dir() / "tests/data/recordings/script_press.rec";
  bool skipped = false;
  const std::string base = "hrep" + std::to_string(::getpid());
  const auto a = replay_against_fresh_server(rec, base + "a_", dir / "a.log", skipped);
  if (skipped) GTEST_SKIP() << "neurosim-server did not answer: " << read_file(dir / "a.log");
  const auto b = replay_against_fresh_server(rec, base + "b_", dir / "b.log", skipped);
  ASSERT_FALSE(skipped) << read_file(dir / "b.log");
  // Which poses a server step picks up depends on timing; the answer to a given pose must not.
  std::size_t common = 0, contact = 0;
  for (const auto& [seq, m] : a) {
    const auto it = b.find(seq);
    if (it == b.end()) continue;
    ++common;
    contact += m.in_contact ? 1 : 0;
    ASSERT_TRUE(m == it->second) << "ContactModel for tool sequence " << seq
                                 << " differs between runs";
  }
  const auto n = neurosim::wire::read_recording(rec).samples.size();
  std::printf("models: run a %zu, run b %zu, common %zu (%zu in contact) of %zu poses\n", a.size(),
              b.size(), common, contact, n);
  // The server answers the newest pose each step, so a loaded machine skips some poses.
  EXPECT_GT(common, n / 4) << "too few poses answered in both runs to compare";
  EXPECT_GT(contact, 100u) << "the replay must actually press into the cube";
  fs::remove_all(dir);
}

TEST(haptic_server, SimulatedHandAgainstTheCubeSettles) {
  // Closed loop with the real physics: the hand pulls the stylus 4 mm into the cube's right
  // face (E = 1 MPa, far stiffer than the Omni may render) for 10 s; the motion must die out.
  // Stability is only judged on a run where the server answered in time throughout (no
  // watchdog timeout: a stalled server fades the force out, and the hand then falls in, which
  // is the safety rule working, not an oscillation); up to 3 runs on a loaded machine. When
  // none of them is timely (seen at load ~13 on 2 cores: the server's threads starved past the
  // 50 ms watchdog), the test gives no verdict (skipped, with the counts) rather than fail on
  // load alone; server latency itself is measured by latency_bench, not judged here.
  if (!fs::exists(server_binary())) GTEST_SKIP() << "no neurosim-server at " << server_binary();
  const fs::path dir = neurosim::testing::temp_dir("haptic_server_hand");
  const std::string prefix = "hhand" + std::to_string(::getpid()) + "_";
  ServerProcess server(prefix, dir / "server.log");
  for (int attempt = 1; attempt <= 3; ++attempt) {
    // A new station each run: the server would reject the jump back to the start pose.
    nh::DdsLink link(server.link_options("hand-" + std::to_string(attempt)));
    WAIT_FOR_SERVER_OR_SKIP(server, link, dir / "server.log");
    nh::HandDevice dev(std::make_unique<nh::ConstantScript>(Vector3d(0, 0, -0.004)));
    dev.set_state(Vector3d(0, 0, 0.004), Vector3d::Zero());  // starts 4 mm in front of the face
    nh::LoopConfig cfg;
    cfg.workspace_origin_m = kFaceOrigin;
    cfg.workspace_up = kFaceNormal;
    cfg.trace_capacity = 11000;
    nh::HapticLoop loop(cfg, dev, &link, nullptr);
    loop.run_realtime(10.0);
    const auto& tr = loop.trace();
    ASSERT_GT(tr.size(), 9000u);
    const auto sum = loop.summary();
    const auto& cnt = loop.force_model().counters();
    std::printf(
        "run %d: model age p99 %.2f ms, misses %llu, timeouts %llu, models %llu, max step %.3f N\n",
        attempt, sum.model_age_p99_ms, static_cast<unsigned long long>(sum.misses_over_1ms),
        static_cast<unsigned long long>(cnt.timeouts),
        static_cast<unsigned long long>(cnt.models_accepted), sum.max_force_step_n);
    if (cnt.timeouts > 0) {
      if (attempt == 3) {
        fs::remove_all(dir);
        GTEST_SKIP() << "no verdict: the server missed the 50 ms watchdog in each of 3 runs of "
                        "10 s (last run: "
                     << cnt.timeouts << " timeouts, model age p99 " << sum.model_age_p99_ms
                     << " ms); the machine is too loaded to judge closed-loop stability";
      }
      continue;
    }
    // Per second: largest speed (from positions); and the last second's speed RMS.
    std::vector<double> vmax(10, 0);
    double v2 = 0;
    std::size_t n_last = 0;
    for (std::size_t i = 1; i < tr.size(); ++i) {
      const double dt = tr[i].t_s - tr[i - 1].t_s;  // the hand is integrated in nominal time
      if (dt <= 0) continue;
      const double v = (tr[i].position_m - tr[i - 1].position_m).norm() / dt;
      const auto s = std::min<std::size_t>(9, static_cast<std::size_t>(tr[i].t_s));
      vmax[s] = std::max(vmax[s], v);
      if (s == 9) {
        v2 += v * v;
        ++n_last;
      }
    }
    const double v_rms_last = std::sqrt(v2 / static_cast<double>(std::max<std::size_t>(n_last, 1)));
    std::printf("hand vs cube: speed max per second (mm/s):");
    for (double v : vmax) std::printf(" %.2f", v * 1e3);
    std::printf("; force %.3f N at the end; speed rms last second %.4f mm/s\n",
                tr.back().force_n.norm(), v_rms_last * 1e3);
    EXPECT_GT(tr.back().force_n.norm(), 0.3) << "the hand must end up pressing on the cube";
    EXPECT_LT(v_rms_last, 1e-3) << "still moving after 10 s: oscillation";
    for (std::size_t s = 4; s < 10; ++s)
      EXPECT_LE(vmax[s], vmax[3] + 1e-3) << "motion grows again in second " << s;
    break;
  }
  fs::remove_all(dir);
}
