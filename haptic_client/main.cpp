// neurosim-haptic: one haptic station.
//   neurosim-haptic --station ID --device SPEC [--duration SECONDS] [--summary FILE.json]
//                   [--record FILE]
//   extra: [--scene FILE] (haptics factors, scene name) [--tool ID] [--origin X,Y,Z]
//          [--up X,Y,Z] [--label TEXT] [--no-server] [--no-rt] [--wait-server SECONDS]
//          [--topic-prefix P] [--trace FILE.csv]
// SPEC: omni[:NAME] | replay:FILE | script:NAME (press, stroke, circle, retract) | hand:SCRIPT
#include "haptic_client/dds_link.hpp"
#include "haptic_client/loop.hpp"

#include "server/scene/scene.hpp"


#include <time.h>
#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>

namespace nh = neurosim::haptic;

namespace {

std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }
void warn(const char* m) { std::fprintf(stderr, "neurosim-haptic: warning: %s\n", m); }

const char* kUsage =
    "usage: neurosim-haptic --station ID --device SPEC [--duration SECONDS] [--summary FILE.json]\n"
    "                       [--record FILE] [--scene FILE] [--tool ID] [--origin X,Y,Z] [--up "
    "X,Y,Z]\n"
    "                       [--label TEXT] [--no-server] [--no-rt] [--wait-server SECONDS]\n"
    "                       [--topic-prefix P]  (P prepended to every topic name, as "
    "neurosim-server's)\n"
    "                       [--trace FILE.csv]  (every tick: time, position, force, model age, "
    "gain)\n"
    "  SPEC: omni[:NAME] | replay:FILE | script:NAME | hand:SCRIPT  (scripts: press, stroke, "
    "circle,\n"
    "        retract). Scripts press along device -z onto a surface at device z = 0; --origin "
    "puts\n"
    "        that point in the scene (m) and --up is the surface's outward normal there.\n";

Eigen::Vector3d parse_vec(const std::string& opt, const std::string& s) {
  Eigen::Vector3d v;
  char c1 = 0, c2 = 0;
  std::istringstream is(s);
  if (!(is >> v.x() >> c1 >> v.y() >> c2 >> v.z()) || c1 != ',' || c2 != ',' || !v.allFinite())
    throw std::invalid_argument(opt + ": expected X,Y,Z (finite numbers), got '" + s + "'");
  return v;
}

double parse_double(const std::string& opt, const std::string& s) {
  std::size_t pos = 0;
  double v = 0;
  try {
    v = std::stod(s, &pos);
  } catch (...) {
    pos = 0;
  }
  if (pos != s.size() || !std::isfinite(v))
    throw std::invalid_argument(opt + ": not a number: '" + s + "'");
  return v;
}

std::int64_t realtime_ns() {
  timespec t{};
  clock_gettime(CLOCK_REALTIME, &t);
  return static_cast<std::int64_t>(t.tv_sec) * 1000000000LL + t.tv_nsec;
}

}  // namespace

int main(int argc, char** argv) {
  std::string station, spec, summary_file, record_file, scene_file, tool = "probe", label,
                                                                    topic_prefix, trace_file;
  double duration = 0, wait_server = 5;
  bool use_server = true;
  nh::LoopConfig cfg;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      auto val = [&]() -> std::string {
        if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
        return argv[++i];
      };
      if (a == "--station")
        station = val();
      else if (a == "--device")
        spec = val();
      else if (a == "--duration")
        duration = parse_double(a, val());
      else if (a == "--summary")
        summary_file = val();
      else if (a == "--record")
        record_file = val();
      else if (a == "--scene")
        scene_file = val();
      else if (a == "--tool")
        tool = val();
      else if (a == "--origin")
        cfg.workspace_origin_m = parse_vec(a, val());
      else if (a == "--up")
        cfg.workspace_up = parse_vec(a, val());
      else if (a == "--label")
        label = val();
      else if (a == "--no-server")
        use_server = false;
      else if (a == "--topic-prefix")
        topic_prefix = val();
      else if (a == "--trace")
        trace_file = val();
      else if (a == "--no-rt")
        cfg.realtime_priority = false;
      else if (a == "--wait-server")
        wait_server = parse_double(a, val());
      else if (a == "-h" || a == "--help") {
        std::cout << kUsage;
        return 0;
      } else
        throw std::invalid_argument("unknown option " + a);
    }
    if (station.empty() || spec.empty())
      throw std::invalid_argument("--station and --device are required");
    if (duration < 0) throw std::invalid_argument("--duration must be >= 0");
  } catch (const std::exception& e) {
    std::cerr << "neurosim-haptic: " << e.what() << "\n" << kUsage;
    return 2;
  }

  try {
    std::string scene_name;
    if (!scene_file.empty()) {
      // The server's loader: the same validation, the same defaults.
      const neurosim::scene::Settings scene = neurosim::scene::load_settings(scene_file);
      scene_name = scene.name;
      cfg.force.force_scale = scene.haptics.force_scale;
      cfg.force.workspace_scale = scene.haptics.workspace_scale;
      cfg.force.max_force_n = scene.haptics.max_force_n;
    }
    std::unique_ptr<nh::Device> device = nh::make_device(spec);
    cfg.force.max_force_n = std::min(cfg.force.max_force_n, device->max_force_n());

    std::unique_ptr<nh::DdsLink> link;
    if (use_server) {
      nh::DdsLinkOptions o;
      o.station_id = station;
      o.tool_id = tool;
      if (!cfg.realtime_priority) o.publisher_rt_priority = o.receiver_rt_priority = 0;  // --no-rt
      o.tool_topic = topic_prefix + o.tool_topic;
      o.model_topic = topic_prefix + o.model_topic;
      o.status_topic = topic_prefix + o.status_topic;
      link = std::make_unique<nh::DdsLink>(o);
      if (wait_server > 0 && !link->wait_for_server(wait_server))
        std::cerr << "neurosim-haptic: no server seen within " << wait_server
                  << " s; running anyway (force stays zero until one answers)\n";
    }
    std::unique_ptr<nh::Recorder> recorder;
    if (!record_file.empty()) {
      if (label.empty()) label = "made with " + device->kind() + " by neurosim-haptic";
      recorder = std::make_unique<nh::Recorder>(
          record_file, nh::session_header(cfg, *device, station, tool, scene_name, scene_file,
                                          label, realtime_ns()));
    }
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);

    // --trace keeps every tick in memory (allocated up front), written after the run.
    cfg.trace_capacity =
        trace_file.empty() ? 0
                           : static_cast<std::size_t>((duration > 0 ? duration : 600) * 1000) + 10;
    cfg.warn = warn;
    nh::HapticLoop loop(cfg, *device, link.get(), recorder.get());
    // Warning printed before the run (the loop itself never prints).
    const nh::RealtimeInfo rt = [&] { return loop.run_realtime(duration, &g_stop); }();
    if (recorder) recorder->close();

    const nh::LoopSummary s = loop.summary();
    const auto& c = loop.force_model().counters();
    std::printf(
        "neurosim-haptic %s: %llu ticks, period p50 %.1f us p99 %.1f us max %.1f us, "
        "%llu ticks > 1 ms late, sched %s\n",
        station.c_str(), static_cast<unsigned long long>(s.samples), s.period_p50_us,
        s.period_p99_us, s.period_max_us, static_cast<unsigned long long>(s.misses_over_1ms),
        rt.sched_fifo ? "SCHED_FIFO" : "normal");
    if (s.model_age_p99_ms >= 0)
      std::printf("  model age p99 %.2f ms, models accepted %llu\n", s.model_age_p99_ms,
                  static_cast<unsigned long long>(c.models_accepted));
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
        "%llu models used\n",
        static_cast<unsigned long long>(ft.contact_ticks),
        s.samples > 0
            ? 100.0 * static_cast<double>(ft.contact_ticks) / static_cast<double>(s.samples)
            : 0.0,
        ft.max_force_n, ft.mean_contact_force_n, static_cast<unsigned long long>(ft.models_seen));
    if (recorder)
      std::printf("  recorded %llu samples to %s (%llu dropped)\n",
                  static_cast<unsigned long long>(recorder->written()), record_file.c_str(),
                  static_cast<unsigned long long>(recorder->dropped()));
    if (!summary_file.empty()) nh::write_summary_json(summary_file, s);
    if (!trace_file.empty()) {
      std::ofstream tf(trace_file);
      if (!tf) throw std::runtime_error(trace_file + ": cannot open for the force trace");
      tf << "t_s,x_m,y_m,z_m,fx_n,fy_n,fz_n,model_age_ms,gain,in_contact,model_sequence\n";
      tf.precision(9);
      for (const auto& t : loop.trace())
        tf << t.t_s << ',' << t.position_m.x() << ',' << t.position_m.y() << ',' << t.position_m.z()
           << ',' << t.force_n.x() << ',' << t.force_n.y() << ',' << t.force_n.z() << ','
           << (t.model_age_s >= 0 ? t.model_age_s * 1e3 : -1) << ',' << t.gain << ','
           << (t.in_contact ? 1 : 0) << ',' << t.model_sequence << '\n';
      if (!tf) throw std::runtime_error(trace_file + ": write failed");
    }
  } catch (const std::exception& e) {
    std::cerr << "neurosim-haptic: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
