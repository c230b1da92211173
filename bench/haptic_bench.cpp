// haptic_bench: the 1 kHz haptic loop for S seconds against a server,
// once at normal priority and once with SCHED_FIFO (where permitted), printing the loop summary.
//
//   haptic_bench [--seconds S] [--modes normal,fifo] [--server PATH --scene FILE] [--csv]
//                [--device SPEC] [--origin X,Y,Z] [--up X,Y,Z] [--spin-us 0,50] [--load N]
// --spin-us: each mode once per value, side by side (0: sleep to the deadline, the old loop;
// 50: sleep, then spin the last 50 µs). --load N: N busy threads run beside the loop.
// Without --server, the ContactModels come from the test-only in-process fake server (a DDS
// thread answering with a half-space spring): the loop, DDS and scheduling are real, the physics
// is not. With --server, neurosim-server is started on --scene with a private topic prefix.
// CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml).
#include "common/cli.hpp"
#include "cpu_load.hpp"
#include "fake_dds_server.hpp"
#include "haptic_client/dds_link.hpp"
#include "haptic_client/loop.hpp"

#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

extern char** environ;
namespace nh = neurosim::haptic;

namespace {

pid_t spawn_server(const std::string& path, const std::string& scene, const std::string& prefix,
                   double seconds) {
  std::vector<std::string> args{
      path, "--scene", scene, "--topic-prefix", prefix, "--duration", std::to_string(seconds)};
  std::vector<char*> argv;
  for (auto& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawn(&pid, path.c_str(), nullptr, nullptr, argv.data(), environ) != 0)
    throw std::runtime_error("cannot start " + path);
  return pid;
}

}  // namespace

int main(int argc, char** argv) {
  double seconds = 60;
  std::string modes = "normal,fifo", server, scene, spec = "hand:press";
  bool csv = false;
  nh::LoopConfig base;
  std::array<double, 3> origin{}, up{};
  neurosim::cli::Parser cli("haptic_bench",
                            "The 1 kHz haptic loop against the fake or the real server.");
  cli.add_option("--seconds", seconds, "seconds per mode")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--modes", modes, "comma-separated: normal, fifo")->capture_default_str();
  cli.add_option("--server", server, "neurosim-server to run (default: a fake server thread)");
  cli.add_option("--scene", scene, "scene for --server");
  cli.add_option("--device", spec, "device SPEC")->capture_default_str();
  auto* origin_opt = cli.add_triple("--origin", origin, "as neurosim-haptic");
  auto* up_opt = cli.add_triple("--up", up, "as neurosim-haptic");
  cli.add_flag("--csv", csv, "print CSV");
  std::string spins = "0,50";
  int load = 0;
  cli.add_option("--spin-us", spins, "comma-separated spin times to compare, unit us")
      ->capture_default_str();
  cli.add_option("--load", load, "busy threads beside the loop (CPU starvation)")
      ->check(neurosim::cli::range(0, 64))
      ->capture_default_str();
  cli.check([&] {
    if (!server.empty() && scene.empty())
      throw neurosim::cli::UsageError("--server needs --scene");
  });
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (origin_opt->count() > 0)
    base.workspace_origin_m = Eigen::Vector3d(origin[0], origin[1], origin[2]);
  if (up_opt->count() > 0) base.workspace_up = Eigen::Vector3d(up[0], up[1], up[2]);
  std::printf(csv ? "mode,server,samples,period_p50_us,period_p99_us,period_max_us,misses_over_1ms,"
                    "model_age_p99_ms,max_force_step_n,sched,spin_us,load\n"
                  : "%-7s %-6s %8s %9s %9s %10s %8s %12s %10s %-10s %7s %4s\n",
              "mode", "server", "samples", "p50_us", "p99_us", "max_us", "misses", "age_p99_ms",
              "step_N", "sched", "spin_us", "load");
  std::vector<std::pair<std::string, double>> runs;  // (mode, spin_us), side by side
  {
    std::stringstream ms(modes);
    std::string m;
    while (std::getline(ms, m, ',')) {
      if (m != "normal" && m != "fifo") {
        std::cerr << "haptic_bench: unknown mode '" << m << "' (normal, fifo)\n";
        return 2;
      }
      std::stringstream ss(spins);
      std::string v;
      while (std::getline(ss, v, ',')) runs.emplace_back(m, std::stod(v));
    }
  }
  const neurosim::bench::CpuLoad cpu_load(load);
  int run = 0;
  for (const auto& [mode, spin_us] : runs) {
    try {
      const std::string prefix =
          "hbench" + std::to_string(::getpid()) + "_" + std::to_string(run++) + "_";
      std::unique_ptr<nh::testing::FakeDdsServer> fake;
      pid_t pid = 0;
      if (server.empty())
        fake = std::make_unique<nh::testing::FakeDdsServer>(prefix, nh::testing::HalfSpace{});
      else
        pid = spawn_server(server, scene, prefix, seconds + 60);
      nh::DdsLinkOptions o;
      o.station_id = "bench";
      o.topic_prefix = prefix;
      if (mode != "fifo") o.publisher_rt_priority = o.receiver_rt_priority = 0;  // all unprivileged
      nh::DdsLink link(o);
      if (!link.wait_for_server(60)) std::cerr << "haptic_bench: no server within 60 s\n";
      auto device = nh::make_device(spec);
      nh::LoopConfig cfg = base;
      cfg.realtime_priority = mode == "fifo";
      cfg.spin_us = spin_us;
      cfg.trace_capacity =
          static_cast<std::size_t>(seconds * 1000) + 10;  // where the longest period was
      nh::HapticLoop loop(cfg, *device, &link, nullptr);
      const nh::RealtimeInfo rt = loop.run_realtime(seconds);
      if (pid > 0) {
        kill(pid, SIGTERM);
        waitpid(pid, nullptr, 0);
      }
      const nh::LoopSummary s = loop.summary();
      const char* sched = rt.sched_fifo ? "SCHED_FIFO" : "normal";
      const char* srv = server.empty() ? "fake" : "real";
      if (csv)
        std::printf("%s,%s,%llu,%.1f,%.1f,%.1f,%llu,%.3f,%.4f,%s,%.0f,%d\n", mode.c_str(), srv,
                    static_cast<unsigned long long>(s.samples), s.period_p50_us, s.period_p99_us,
                    s.period_max_us, static_cast<unsigned long long>(s.misses_over_1ms),
                    s.model_age_p99_ms, s.max_force_step_n, sched, spin_us, load);
      else
        std::printf("%-7s %-6s %8llu %9.1f %9.1f %10.1f %8llu %12.3f %10.4f %-10s %7.0f %4d\n",
                    mode.c_str(), srv, static_cast<unsigned long long>(s.samples),
                    s.period_p50_us, s.period_p99_us, s.period_max_us,
                    static_cast<unsigned long long>(s.misses_over_1ms), s.model_age_p99_ms,
                    s.max_force_step_n, sched, spin_us, load);
      if (!rt.warning.empty()) std::fprintf(stderr, "haptic_bench: %s\n", rt.warning.c_str());
      const auto& tr = loop.trace();
      std::size_t worst = 0;
      for (std::size_t i = 1; i < tr.size(); ++i)
        if (tr[i].now_ns - tr[i - 1].now_ns >
            tr[worst].now_ns - (worst > 0 ? tr[worst - 1].now_ns : tr[0].now_ns))
          worst = i;
      if (worst > 0)
        std::fprintf(
            stderr, "haptic_bench (%s): longest period %.1f us before tick %zu (t = %.3f s)\n",
            mode.c_str(), 1e-3 * static_cast<double>(tr[worst].now_ns - tr[worst - 1].now_ns),
            worst, tr[worst].t_s);
      std::fflush(stdout);
    } catch (const std::exception& e) {
      std::cerr << "haptic_bench (" << mode << "): " << e.what() << "\n";
      return 1;
    }
  }
  return 0;
}
