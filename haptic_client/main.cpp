// neurosim-haptic: one haptic station.
//   neurosim-haptic --station ID --device SPEC [--duration SECONDS] [--summary FILE.json]
//                   [--record FILE]
//   extra: [--scene FILE] (haptics factors, scene name) [--tool ID] [--origin X,Y,Z]
//          [--up X,Y,Z] [--label TEXT] [--no-server] [--no-rt] [--wait-server SECONDS]
//          [--topic-prefix P] [--trace FILE.csv] [--spin-us US]
//          [--rt-priority loop=80,publisher=70,receiver=60] [--rt-cpus loop=1]
// SPEC: omni[:NAME] | replay:FILE | script:NAME (press, stroke, circle, retract, approach, hold[:S]) | hand:SCRIPT
// --help lists the options, --version prints the version; usage errors exit 2.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/thread_sched.hpp"
#include "haptic_client/dds_link.hpp"
#include "haptic_client/loop.hpp"

#include "server/scene/scene.hpp"


#include <array>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>

namespace nh = neurosim::haptic;

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }
void warn(const char* m) { std::fprintf(stderr, "neurosim-haptic: warning: %s\n", m); }
void sched_line(const char* m) { std::fprintf(stderr, "neurosim-haptic: %s\n", m); }
// A clock difference in ns as seconds with nine decimals (exact to the ns, whatever its size).
std::string clock_s(std::int64_t ns) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.9f", 1e-9 * static_cast<double>(ns));
  return buf;
}

const char* kSpecHelp =
    "SPEC: omni[:NAME] | replay:FILE | script:NAME | hand:SCRIPT  (scripts: press, stroke, circle,\n"
    "      retract, approach, hold[:S]: the press held S s, default 10). Scripts press along\n"
    "      device -z onto a surface at device z = 0;\n"
    "      --origin puts that point in the scene (m) and --up is the surface's outward normal\n"
    "      there. approach goes through a craniotomy: use it with --at-opening.";

}  // namespace

int main(int argc, char** argv) {
  std::string station, spec, summary_file, record_file, scene_file, tool = "probe", label,
                                                                    topic_prefix, trace_file;
  double duration = 0, wait_server = 5;
  bool no_server = false, no_rt = false;
  std::array<double, 3> origin{}, up{};
  nh::LoopConfig cfg;
  neurosim::cli::Parser cli("neurosim-haptic", "One haptic station: the 1 kHz force loop.");
  cli.add_option("--station", station, "station id")->required();
  cli.add_option("--device", spec, "device SPEC (below)")->required();
  cli.add_option("--duration", duration, "stop after S seconds (default 0: until a signal)")
      ->check(neurosim::cli::non_negative());
  cli.add_option("--summary", summary_file, "write the loop summary as JSON");
  cli.add_option("--record", record_file, "record the session");
  cli.add_option("--scene", scene_file, "scene file (haptics factors, scene name)");
  cli.add_option("--tool", tool, "tool id")->capture_default_str();
  auto* origin_opt =
      cli.add_triple("--origin", origin, "where device z = 0 is in the scene, unit m");
  auto* up_opt = cli.add_triple("--up", up, "the surface's outward normal there");
  bool at_opening = false;
  cli.add_flag("--at-opening", at_opening,
               "origin: the centre of the scene's craniotomy (its first rigid mesh opening, on "
               "the brain surface), up: its axis out of the head (needs --scene; for "
               "script:approach)")
      ->excludes(origin_opt)
      ->excludes(up_opt);
  cli.add_option("--label", label, "recording label");
  cli.add_flag("--no-server", no_server, "run without DDS (no force from a server)");
  auto* no_rt_opt =
      cli.add_flag("--no-rt", no_rt, "no SCHED_FIFO for the loop and the DDS threads");
  // The client's threads in one place: loop, publisher (ToolState), receiver (ContactModel).
  neurosim::common::ThreadPlan threads;
  threads.threads = {{"loop", "nh-loop", 80, {}},
                     {"publisher", "nh-publish", 70, {}},
                     {"receiver", "nh-receive", 60, {}}};
  std::string rt_priority, rt_cpus;
  cli.add_option("--rt-priority", rt_priority,
                 "thread priorities, ROLE=P,... (roles loop, publisher, receiver; P 1..99 "
                 "SCHED_FIFO, 0 normal; default " +
                     threads.priorities_text() + ")")
      ->excludes(no_rt_opt);
  cli.add_option("--rt-cpus", rt_cpus,
                 "CPU sets, ROLE=CPUS,... (CPUS: numbers and ranges joined by '+'; default any)");
  cli.add_option("--spin-us", cfg.spin_us,
                 "spin on the clock this long before each tick, unit us (0: off, for laptops on "
                 "battery)")
      ->check(neurosim::cli::range(0.0, 900.0))
      ->capture_default_str();
  cli.add_option("--wait-server", wait_server, "wait this long for a server, unit s")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  cli.add_option("--topic-prefix", topic_prefix,
                 "prepended to every topic name, as neurosim-server's");
  cli.add_option("--trace", trace_file,
                 "every tick as CSV: time, position, force, model age, gain, rigid wall, and "
                 "the loop clock (clock_s: a late tick shows there, t_s is the nominal k T)");
  cli.footer(kSpecHelp);
  if (auto rc = cli.parse(argc, argv)) return *rc;
  if (origin_opt->count() > 0)
    cfg.workspace_origin_m = Eigen::Vector3d(origin[0], origin[1], origin[2]);
  if (up_opt->count() > 0) cfg.workspace_up = Eigen::Vector3d(up[0], up[1], up[2]);
  try {
    neurosim::common::apply_priorities(threads, rt_priority, "--rt-priority");
    neurosim::common::apply_cpus(threads, rt_cpus, "--rt-cpus");
  } catch (const std::invalid_argument& e) {
    std::cerr << "neurosim-haptic: " << e.what() << "\n";
    return 2;
  }
  if (no_rt)
    for (auto& t : threads.threads) t.priority = 0;
  cfg.rt_priority = threads.at("loop").priority;
  cfg.realtime_priority = cfg.rt_priority > 0;
  cfg.thread_name = threads.at("loop").name;
  cfg.cpus = threads.at("loop").cpus;
  cfg.sched_log = sched_line;
  const bool use_server = !no_server;

  try {
    std::string scene_name;
    if (!scene_file.empty()) {
      // The server's loader: the same validation, the same defaults.
      const neurosim::scene::Settings scene = neurosim::scene::load_settings(scene_file);
      scene_name = scene.name;
      cfg.force.force_scale = scene.haptics.force_scale;
      cfg.force.workspace_scale = scene.haptics.workspace_scale;
      cfg.force.max_force_n = scene.haptics.max_force_n;
      if (at_opening) {
        if (scene.openings.empty())
          throw std::invalid_argument("--at-opening: scene " + scene_file +
                                      " has no rigid mesh with an opening");
        const auto& o = scene.openings.front();
        cfg.workspace_origin_m = Eigen::Vector3d(o.center_m[0], o.center_m[1], o.center_m[2]);
        cfg.workspace_up = Eigen::Vector3d(o.axis[0], o.axis[1], o.axis[2]);
        std::fprintf(stderr,
                     "neurosim-haptic: workspace at the opening of '%s': centre (%.4f, %.4f, "
                     "%.4f) m, axis (%.3f, %.3f, %.3f), radius %.1f mm\n",
                     o.mesh.c_str(), o.center_m[0], o.center_m[1], o.center_m[2], o.axis[0],
                     o.axis[1], o.axis[2], o.radius_m * 1e3);
      }
    } else if (at_opening) {
      throw std::invalid_argument("--at-opening needs --scene FILE (the scene with the opening)");
    }
    std::unique_ptr<nh::Device> device = nh::make_device(spec);
    cfg.force.max_force_n = std::min(cfg.force.max_force_n, device->max_force_n());

    std::unique_ptr<nh::DdsLink> link;
    if (use_server) {
      nh::DdsLinkOptions o;
      o.station_id = station;
      o.tool_id = tool;
      o.publisher_rt_priority = threads.at("publisher").priority;
      o.receiver_rt_priority = threads.at("receiver").priority;
      o.publisher_thread_name = threads.at("publisher").name;
      o.receiver_thread_name = threads.at("receiver").name;
      o.publisher_cpus = threads.at("publisher").cpus;
      o.receiver_cpus = threads.at("receiver").cpus;
      o.sched_log = sched_line;
      o.topic_prefix = topic_prefix;
      link = std::make_unique<nh::DdsLink>(o);
      if (wait_server > 0 && !link->wait_for_server(wait_server))
        std::cerr << "neurosim-haptic: no server seen within " << wait_server
                  << " s; running anyway (force stays zero until one answers)\n";
    }
    std::unique_ptr<nh::Recorder> recorder;
    // A recording that fails (read-only or full folder, at the start or mid-session) is said at
    // once; the session goes on without it and the exit status is 1.
    std::string recording_error;
    if (!record_file.empty()) {
      if (label.empty()) label = "made with " + device->kind() + " by neurosim-haptic";
      try {
        recorder = std::make_unique<nh::Recorder>(
            record_file, nh::session_header(cfg, *device, station, tool, scene_name, scene_file,
                                            label, neurosim::common::realtime_ns()));
      } catch (const std::runtime_error& e) {  // e.g. a read-only or full folder
        recording_error = e.what();
        std::cerr << "neurosim-haptic: " << recording_error
                  << "; the session goes on without the recording\n";
      }
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);

    // --trace keeps every tick in memory (allocated up front), written after the run.
    cfg.trace_capacity =
        trace_file.empty() ? 0
                           : static_cast<std::size_t>((duration > 0 ? duration : 600) * 1000) + 10;
    cfg.warn = warn;
    nh::HapticLoop loop(cfg, *device, link.get(), recorder.get());
    // A refusal by the server is said at once (SimStatus.refused, within ~0.2 s of the first
    // refused sample): a permanent one ends the session (exit status 3), max_stations waits.
    std::atomic<bool> loop_done{false};
    std::atomic<int> refused_exit{0};
    std::thread refusal_watch;
    if (link) {
      refusal_watch = std::thread([&] {
        nh::Refusal said = nh::Refusal::None;
        while (!loop_done.load()) {
          const nh::Refusal r = link->refusal();
          if (r != nh::Refusal::None && r != said) {
            said = r;
            std::cerr << "neurosim-haptic: error: station '" << station << "' refused by the server: "
                      << nh::describe(r) << (nh::permanent(r) ? "; exiting\n" : "\n") << std::flush;
            if (nh::permanent(r)) {
              refused_exit = 3;
              g_stop = true;
              return;
            }
          }
          std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
      });
    }
    // Warning printed before the run (the loop itself never prints).
    const nh::RealtimeInfo rt = [&] { return loop.run_realtime(duration, &g_stop); }();
    loop_done = true;
    if (refusal_watch.joinable()) refusal_watch.join();
    if (recorder) {
      try {
        recorder->close();
      } catch (const std::exception& e) {
        recording_error = e.what();
      }
    }

    const nh::LoopSummary s = loop.summary();
    const auto& c = loop.force_model().counters();
    std::printf(
        "neurosim-haptic %s: %llu ticks, period p50 %.1f us p99 %.1f us max %.1f us, "
        "%llu ticks > 1 ms late, sched %s\n",
        station.c_str(), static_cast<unsigned long long>(s.samples), s.period_p50_us,
        s.period_p99_us, s.period_max_us, static_cast<unsigned long long>(s.misses_over_1ms),
        rt.sched_fifo ? "SCHED_FIFO" : "normal");
    if (s.model_age_p99_ms >= 0) {
      std::printf("  model age p99 %.2f ms, models accepted %llu", s.model_age_p99_ms,
                  static_cast<unsigned long long>(c.models_accepted));
      if (link)
        std::printf(", server steps without a model here %llu",
                    static_cast<unsigned long long>(link->counters().models_skipped));
      std::printf("\n");
    }
    else
      std::printf("  no ContactModel received\n");
    std::printf(
        "  max force step %.4f N, errors: nan inputs %llu, nan models %llu, timeouts %llu, "
        "server lost %llu, stiffness limited %llu\n",
        s.max_force_step_n, static_cast<unsigned long long>(c.nan_inputs),
        static_cast<unsigned long long>(c.nan_models), static_cast<unsigned long long>(c.timeouts),
        static_cast<unsigned long long>(c.server_lost),
        static_cast<unsigned long long>(c.stiffness_limited));
    const nh::ForceTraceSummary ft = loop.force_trace();
    std::printf(
        "  force trace: %llu ticks in contact (%.1f %%), max |F| %.3f N, mean |F| in contact %.3f "
        "N, "
        "%llu models used, %llu ignored (answering no pose of this station)\n",
        static_cast<unsigned long long>(ft.contact_ticks),
        s.samples > 0
            ? 100.0 * static_cast<double>(ft.contact_ticks) / static_cast<double>(s.samples)
            : 0.0,
        ft.max_force_n, ft.mean_contact_force_n, static_cast<unsigned long long>(ft.models_seen),
        static_cast<unsigned long long>(ft.foreign_models));
    std::printf(
        "  rigid wall: %llu ticks in rigid contact, max wall force %.3f N, max depth behind the "
        "proxy %.2f mm, planes dropped %llu, infeasible plane sets %llu\n",
        static_cast<unsigned long long>(ft.rigid_contact_ticks), ft.max_wall_force_n,
        ft.max_wall_penetration_m * 1e3,
        static_cast<unsigned long long>(c.planes_dropped +
                                        (link ? link->counters().planes_dropped : 0)),
        static_cast<unsigned long long>(c.planes_infeasible));
    if (recorder && recording_error.empty())
      std::printf("  recorded %llu samples to %s (%llu dropped)\n",
                  static_cast<unsigned long long>(recorder->written()), record_file.c_str(),
                  static_cast<unsigned long long>(recorder->dropped()));
    if (!summary_file.empty()) nh::write_summary_json(summary_file, s);
    if (!trace_file.empty()) {
      std::ofstream tf(trace_file);
      if (!tf) throw std::runtime_error(trace_file + ": cannot open for the force trace");
      tf << "t_s,x_m,y_m,z_m,fx_n,fy_n,fz_n,model_age_ms,gain,in_contact,model_sequence,"
            "rigid_contact,proxy_x_m,proxy_y_m,proxy_z_m,wall_fx_n,wall_fy_n,wall_fz_n,clock_s\n";
      tf.precision(9);
      const std::int64_t first_ns = loop.trace().empty() ? 0 : loop.trace().front().now_ns;
      for (const auto& t : loop.trace())
        tf << t.t_s << ',' << t.position_m.x() << ',' << t.position_m.y() << ',' << t.position_m.z()
           << ',' << t.force_n.x() << ',' << t.force_n.y() << ',' << t.force_n.z() << ','
           << (t.model_age_s >= 0 ? t.model_age_s * 1e3 : -1) << ',' << t.gain << ','
           << (t.in_contact ? 1 : 0) << ',' << t.model_sequence << ',' << (t.rigid_contact ? 1 : 0)
           << ',' << t.proxy_m.x() << ',' << t.proxy_m.y() << ',' << t.proxy_m.z() << ','
           << t.wall_force_n.x() << ',' << t.wall_force_n.y() << ',' << t.wall_force_n.z() << ','
           << clock_s(t.now_ns - first_ns) << '\n';
      if (!tf) throw std::runtime_error(trace_file + ": write failed");
    }
    if (!recording_error.empty()) {
      std::cerr << "neurosim-haptic: " << recording_error << "\n";
      return 1;
    }
    if (refused_exit.load() != 0) return refused_exit.load();
  } catch (const std::exception& e) {
    std::cerr << "neurosim-haptic: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
