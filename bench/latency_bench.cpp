// latency_bench: starts neurosim-server on a bundled scene (child process, private DDS
// domain, loopback) and N scripted stations (one participant and thread each, 1 kHz on absolute
// deadlines, every tool pressing into the cube's +x face), and measures for each ToolState the
// time until the ContactModel answering it (tool_sequence) is read by that station.
//
//   latency_bench --stations N --seconds S [--csv] [--scene FILE] [--server EXE] [--warmup S]
//                 [--viewer]   also read Deformation, so the server runs its full-field solves
//                 [--load N]   N busy threads beside server and stations (CPU starvation)
//                 [--report-every S]  soak: also one row per S seconds (latency of the answers
//                              in that interval, lost, server RSS and step p99 at its end,
//                              non-finite ContactModels over the run), e.g. --stations 4 --viewer --seconds 600
//                              --report-every 60
//                 [--step-modes event,clock]  one server run per step mode, one row each
//                              (neurosim-server --step-mode; default: event)
//                 [--contact default,barycentric,...]  one server run per contact configuration,
//                              one row each: "default" (the library's contact options) or items
//                              joined by '+': barycentric, spread=X, smooth-normals=on|off,
//                              near-field=on|off (neurosim-server --barycentric-contact,
//                              --contact-spread X, --contact-smooth-normals, --contact-near-field),
//                              e.g. --contact default,barycentric,spread=1+near-field=off
//                 [--repeat N]  the whole list of runs (modes x contact configurations) N times,
//                              interleaved, so configurations are compared under the same load
//
// CSV: stations,samples,p50_us,p99_us,max_us,lost,server_cpu_pct,load,mode,contact
//   samples        ToolStates answered during the measurement (after the warm-up)
//   lost           ContactModels the server wrote for a station that the station never read
//                  (gaps in ContactModel.server_step), all stations
//   server_cpu_pct server process CPU time / wall time over the measurement, % of one core
//   contact        the --contact configuration
//   step_p50_us, step_p99_us  the server's own step time (step thread, the step and its
//                  ContactModel writes) over its last SimStatus period; -1: no SimStatus read
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/process_stats.hpp"
#include "common/stats.hpp"
#include "cpu_load.hpp"
#include "idl/wire/dds.hpp"

#include <fcntl.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace wire = neurosim::wire;
namespace fs = std::filesystem;

namespace {

using neurosim::common::monotonic_ns;


struct Options {
  int stations = 1;
  double seconds = 5;
  double warmup_s = 1.0;
  bool csv = false;
  bool viewer = false;  // also read Deformation (the server then runs full-field solves)
  fs::path scene = fs::path(NEUROSIM_SOURCE_DIR) / "scenes/cube_cylinder.scene";
  fs::path server;
  double startup_timeout_s = 300;
};

// Station k's contact point on the cube's +x face (x = 0.1 m), spread over the face.
void station_point(int k, int n, double p[3]) {
  const double a = 2 * M_PI * k / std::max(1, n);
  p[0] = 0.1;
  p[1] = 0.05 + (n > 1 ? 0.025 * std::cos(a) : 0.0);
  p[2] = 0.05 + (n > 1 ? 0.025 * std::sin(a) : 0.0);
}

// One --contact configuration: its name (the CSV's contact column) and neurosim-server's switches.
struct ContactConfig {
  std::string name;
  std::vector<std::string> server_args;
};

// "default" or items joined by '+' (see the header); throws std::invalid_argument naming the item.
ContactConfig parse_contact(const std::string& text) {
  ContactConfig c{text, {}};
  if (text == "default") return c;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, '+');) {
    const auto eq = item.find('=');
    const std::string key = item.substr(0, eq), value = eq == std::string::npos ? "" : item.substr(eq + 1);
    if (item == "barycentric") {
      c.server_args.push_back("--barycentric-contact");
    } else if (key == "spread" && !value.empty()) {
      c.server_args.insert(c.server_args.end(), {"--contact-spread", value});
    } else if ((key == "smooth-normals" || key == "near-field") && (value == "on" || value == "off")) {
      c.server_args.insert(c.server_args.end(), {"--contact-" + key, value});
    } else {
      throw std::invalid_argument("--contact: unknown item '" + item + "' in '" + text +
                                  "' (default, or barycentric, spread=X, smooth-normals=on|off, "
                                  "near-field=on|off joined by '+')");
    }
  }
  if (c.server_args.empty()) throw std::invalid_argument("--contact: empty configuration in '" + text + "'");
  return c;
}

struct StationResult {
  std::vector<double> latency_us;
  std::vector<std::int64_t> latency_at_ns;  // when each answer was read (CLOCK_MONOTONIC)
  std::vector<std::pair<std::int64_t, std::uint64_t>> lost_at;  // (when, how many)
  std::uint64_t nonfinite = 0;  // ContactModels with a NaN/inf force or stiffness
  std::uint64_t lost = 0;
  std::uint64_t sent = 0;
};

bool own_station(const void* sample, void* arg) {
  return std::strcmp(static_cast<const neurosim_ContactModel*>(sample)->station_id,
                     static_cast<const char*>(arg)) == 0;
}

// One station: writes at 1 kHz, and between writes waits for and reads its ContactModels.
struct Window {
  std::atomic<std::int64_t> from{0}, to{0};  // CLOCK_MONOTONIC, unit ns; set before go
};

void run_station(int domain, int k, int n, const Window& window, std::atomic<int>& ready,
                 const std::atomic<bool>& go, StationResult& out) {
  // Like a haptic loop: real-time priority where allowed (below the server's step thread).
  sched_param sp{};
  sp.sched_priority = 40;
  pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
  wire::ParticipantOptions po;
  po.domain = static_cast<dds_domainid_t>(domain);
  wire::Participant pp(po);
  const std::string id = "bench-" + std::to_string(k);
  std::vector<char> id_arg(id.begin(), id.end());
  id_arg.push_back('\0');
  wire::Topic<neurosim_ToolState> tt(pp);
  wire::Topic<neurosim_ContactModel> mt(pp);
  // Only this station's models reach its reader (a haptic client reads its own key).
  wire::check(dds_set_topic_filter_and_arg(mt.handle(), own_station, id_arg.data()), "set topic filter");
  wire::Writer<neurosim_ToolState> w(pp, tt, id);  // in the station's partition
  // History 16 instead of the profile's 1: "lost" must count models the transport lost, not
  // ones a briefly descheduled station overwrote in its own cache (e.g. two steps back to back
  // after a late server wake-up). A haptic client keeps 1: it only needs the newest.
  wire::Qos rq = wire::reader_qos(wire::Profile::ContactModel);
  dds_qset_history(rq.get(), DDS_HISTORY_KEEP_LAST, 16);
  wire::Reader<neurosim_ContactModel> r(pp, mt, rq);
  wire::Waitset ws(pp);
  ws.attach_data(r, 1);
  w.wait_for_readers(1, DDS_SECS(30));
  r.wait_for_writers(1, DDS_SECS(30));
  ++ready;
  while (!go.load()) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  const std::int64_t measure_from = window.from.load(), measure_to = window.to.load();

  constexpr std::size_t kRing = 1 << 14;
  std::vector<std::int64_t> sent_at(kRing, 0);
  double base[3];
  station_point(k, n, base);
  wire::Sample<neurosim_ToolState> s;
  wire::set_string(s->station_id, id, "station_id");
  wire::set_string(s->tool_id, "probe", "tool_id");
  s->orientation[0] = 1;
  std::uint64_t seq = 0, answered = 0, last_step = 0;
  out.latency_us.reserve(static_cast<std::size_t>((measure_to - measure_from) / 1000000 + 1000));
  std::int64_t next = monotonic_ns();
  const std::int64_t t_start = next;
  while (next < measure_to + 200000000LL) {
    const std::int64_t now = monotonic_ns();
    if (now >= next) {
      // Press 1.5 to 2.5 mm into the face (tip radius 3 mm), slowly in and out.
      const double t = 1e-9 * static_cast<double>(now - t_start);
      s->position_m[0] = base[0] + 0.003 - 0.002 - 0.0005 * std::sin(2 * M_PI * 0.5 * t);
      s->position_m[1] = base[1];
      s->position_m[2] = base[2];
      s->sequence_number = ++seq;
      s->source_time_ns = dds_time();
      sent_at[seq % kRing] = monotonic_ns();
      w.write(*s);
      if (now >= measure_from && now < measure_to) ++out.sent;
      next += 1000000;
      continue;
    }
    ws.wait(next - now);
    for (const auto& rx : r.take()) {
      if (!rx.valid()) continue;
      const std::int64_t got = monotonic_ns();
      const auto& m = rx.data;
      if (got >= measure_from && got < measure_to) {
        if (last_step != 0 && m.server_step > last_step + 1) {
          out.lost += m.server_step - last_step - 1;
          out.lost_at.emplace_back(got, m.server_step - last_step - 1);
        }
        if (m.tool_sequence > answered && m.tool_sequence + kRing > seq) {
          out.latency_us.push_back(1e-3 * static_cast<double>(got - sent_at[m.tool_sequence % kRing]));
          out.latency_at_ns.push_back(got);
        }
        bool finite = true;
        for (double v : m.f0_n) finite = finite && std::isfinite(v);
        for (double v : m.stiffness_n_per_m) finite = finite && std::isfinite(v);
        if (!finite) ++out.nonfinite;
      }
      last_step = m.server_step;
      answered = std::max<std::uint64_t>(answered, m.tool_sequence);
    }
  }
}



}  // namespace

int main(int argc, char** argv) {
  Options o;
  o.server = fs::read_symlink("/proc/self/exe").parent_path() / "neurosim-server";
  std::string scene = o.scene.string(), server = o.server.string();
  neurosim::cli::Parser cli("latency_bench",
                            "ToolState to ContactModel latency over DDS on loopback.");
  cli.add_option("--stations", o.stations, "stations 1..8")
      ->check(neurosim::cli::in_range(1, 8))
      ->capture_default_str();
  cli.add_option("--seconds", o.seconds, "measured seconds")
      ->check(neurosim::cli::positive())
      ->capture_default_str();
  cli.add_option("--warmup", o.warmup_s, "warm-up seconds")
      ->check(neurosim::cli::finite())
      ->capture_default_str();
  cli.add_option("--scene", scene, "scene file")->capture_default_str();
  cli.add_option("--server", server, "neurosim-server executable")->capture_default_str();
  cli.add_flag("--csv", o.csv, "print CSV");
  cli.add_flag("--viewer", o.viewer, "also subscribe to Deformation (full-field solves run)");
  int load = 0;
  cli.add_option("--load", load, "busy threads beside the measured processes")
      ->check(neurosim::cli::in_range(0, 64))
      ->capture_default_str();
  double report_every_s = 0;
  cli.add_option("--report-every", report_every_s,
                 "soak: one row per this many seconds, unit s (0: none)")
      ->check(neurosim::cli::non_negative())
      ->capture_default_str();
  std::string modes_text = "event";
  cli.add_option("--step-modes", modes_text,
                 "comma-separated server step modes to compare side by side (event, clock)")
      ->capture_default_str();
  std::string contact_text = "default";
  cli.add_option("--contact", contact_text,
                 "comma-separated contact configurations to compare side by side: default, or "
                 "barycentric, spread=X, smooth-normals=on|off, near-field=on|off joined by '+' "
                 "(neurosim-server's contact switches; the server refuses contradictions)")
      ->capture_default_str();
  int repeat = 1;
  cli.add_option("--repeat", repeat,
                 "run the whole list of configurations this many times, interleaved")
      ->check(neurosim::cli::in_range(1, 100))
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  std::vector<ContactConfig> contacts;
  try {
    std::stringstream ss(contact_text);
    for (std::string c; std::getline(ss, c, ',');) contacts.push_back(parse_contact(c));
    if (contacts.empty()) throw std::invalid_argument("--contact: no configuration given");
  } catch (const std::invalid_argument& e) {
    std::cerr << "latency_bench: " << e.what() << "\n";
    return 2;
  }
  std::vector<std::string> modes;
  {
    std::stringstream ss(modes_text);
    for (std::string m; std::getline(ss, m, ',');) {
      if (m != "event" && m != "clock") {
        std::cerr << "latency_bench: --step-modes: unknown mode '" << m << "' (event, clock)\n";
        return 2;
      }
      modes.push_back(m);
    }
    if (modes.empty()) {
      std::cerr << "latency_bench: --step-modes: no mode given\n";
      return 2;
    }
  }
  o.scene = scene;
  o.server = server;
  // Loopback only (docs/ARCHITECTURE.md "DDS"): the bench sets it for itself and the server when unset.
  setenv("CYCLONEDDS_URI", NEUROSIM_LOOPBACK_URI, 0);
  int rc = 0;
  if (o.csv) std::printf("stations,samples,p50_us,p99_us,max_us,lost,server_cpu_pct,load,mode,contact,step_p50_us,step_p99_us\n");
  struct Run {
    std::string mode;
    const ContactConfig* contact;
  };
  std::vector<Run> runs;
  for (int k = 0; k < repeat; ++k)
    for (const std::string& m : modes)
      for (const ContactConfig& c : contacts) runs.push_back({m, &c});
  for (const Run& run : runs) {
  const std::string& mode = run.mode;
  const ContactConfig& contact = *run.contact;
  std::random_device rd;
  const int domain = 20 + static_cast<int>(rd() % 200);
  const fs::path log = fs::temp_directory_path() / ("latency_bench_server_" + std::to_string(getpid()) + ".log");

  // The server, bounded by --duration even if this process dies.
  const double server_duration = o.startup_timeout_s + o.warmup_s + o.seconds + 30;
  std::vector<std::string> args{o.server.string(), "--scene", o.scene.string(), "--domain", std::to_string(domain),
                                "--duration", std::to_string(server_duration), "--server-id", "latency_bench", "--step-mode", mode};
  args.insert(args.end(), contact.server_args.begin(), contact.server_args.end());
  std::vector<char*> av;
  for (auto& a : args) av.push_back(a.data());
  av.push_back(nullptr);
  const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  const pid_t pid = fork();
  if (pid == 0) {
    dup2(fd, 1);
    dup2(fd, 2);
    execv(av[0], av.data());
    _exit(127);
  }
  close(fd);
  auto stop_server = [&] {
    kill(pid, SIGTERM);
    for (int i = 0; i < 1000; ++i) {
      int st = 0;
      if (waitpid(pid, &st, WNOHANG) == pid) return;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  };

  const neurosim::bench::CpuLoad cpu_load(load);  // after the fork: the server starts unloaded
  try {
    // Ready = the server published SimStatus.
    wire::ParticipantOptions po;
    po.domain = static_cast<dds_domainid_t>(domain);
    wire::Participant pp(po);
    wire::Topic<neurosim_SimStatus> stt(pp);
    wire::Reader<neurosim_SimStatus> status(pp, stt);
    std::optional<wire::Topic<neurosim_Deformation>> dt;
    std::optional<wire::Reader<neurosim_Deformation>> viewer;
    if (o.viewer) {
      dt.emplace(pp);
      viewer.emplace(pp, *dt);
    }
    const auto t0 = std::chrono::steady_clock::now();
    bool ready = false;
    while (!ready && std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < o.startup_timeout_s) {
      ready = status.take_newest() != nullptr;
      int st = 0;
      if (waitpid(pid, &st, WNOHANG) == pid) throw std::runtime_error("the server exited; log: " + log.string());
      if (!ready) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    if (!ready) throw std::runtime_error("no SimStatus from the server; log: " + log.string());

    std::atomic<int> n_ready{0};
    std::atomic<bool> go{false};
    Window window;
    std::vector<StationResult> results(static_cast<std::size_t>(o.stations));
    std::vector<std::string> errors(static_cast<std::size_t>(o.stations));
    std::vector<std::thread> threads;
    for (int k = 0; k < o.stations; ++k)
      threads.emplace_back([&, k] {
        try {
          run_station(domain, k, o.stations, window, n_ready, go, results[static_cast<std::size_t>(k)]);
        } catch (const std::exception& e) {
          errors[static_cast<std::size_t>(k)] = e.what();
          ++n_ready;
        }
      });
    const auto t1 = std::chrono::steady_clock::now();
    while (n_ready.load() < o.stations &&
           std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count() < 60)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    const std::int64_t from = monotonic_ns() + static_cast<std::int64_t>(o.warmup_s * 1e9);
    const std::int64_t to = from + static_cast<std::int64_t>(o.seconds * 1e9);
    window.from = from;
    window.to = to;
    go = true;
    const auto sleep_until = [](std::int64_t t) { neurosim::common::sleep_until_ns(t); };
    sleep_until(from);
    const double cpu0 = neurosim::common::cpu_seconds(pid);
    // Soak rows: the server's RSS and newest step p99 at the end of each interval.
    struct Interval {
      std::int64_t end_ns;
      long rss_kb;
      double step_p99_us;
    };
    std::vector<Interval> intervals;
    char last_status[256] = "no SimStatus";
    double step_p50_us = -1, step_p99_us = -1;
    if (report_every_s > 0) {
      const auto every_ns = static_cast<std::int64_t>(report_every_s * 1e9);
      for (std::int64_t t = from + every_ns; t <= to; t += every_ns) {
        sleep_until(t);
        double p99_step = -1;
        for (const auto& rx : status.take())
          if (rx.valid()) {
            p99_step = rx.data.step_time_p99_us;
            step_p50_us = rx.data.step_time_p50_us;
            step_p99_us = rx.data.step_time_p99_us;
            std::snprintf(last_status, sizeof last_status,
                          "step p50 %.1f us, p99 %.1f us, max %.1f us, %llu deadline misses",
                          rx.data.step_time_p50_us, rx.data.step_time_p99_us, rx.data.step_time_max_us,
                          static_cast<unsigned long long>(rx.data.deadline_misses));
          }
        intervals.push_back({t, neurosim::common::resident_kib(pid), p99_step});
      }
    }
    sleep_until(to);
    const double cpu1 = neurosim::common::cpu_seconds(pid);
    // The server's own step times over the last status period (SimStatus, 1 Hz).
    std::string step_text = last_status;
    if (const auto* st = status.take_newest()) {
      char buf[256];
      std::snprintf(buf, sizeof buf, "step p50 %.1f us, p99 %.1f us, max %.1f us, %llu deadline misses",
                    st->step_time_p50_us, st->step_time_p99_us, st->step_time_max_us,
                    static_cast<unsigned long long>(st->deadline_misses));
      step_text = buf;
      step_p50_us = st->step_time_p50_us;
      step_p99_us = st->step_time_p99_us;
    }
    std::size_t frames = 0;
    if (viewer) frames = viewer->take().size();
    for (auto& t : threads) t.join();
    for (const auto& e : errors)
      if (!e.empty()) throw std::runtime_error("station: " + e);
    std::vector<double> all;
    std::uint64_t lost = 0, sent = 0;
    for (const auto& r : results) {
      all.insert(all.end(), r.latency_us.begin(), r.latency_us.end());
      lost += r.lost;
      sent += r.sent;
    }
    const double cpu_pct = 100.0 * (cpu1 - cpu0) / o.seconds;
    if (!intervals.empty()) {
      std::printf("soak,%s,interval_end_s,samples,p50_us,p99_us,max_us,lost,server_rss_kb,step_p99_us,nonfinite_total\n",
                  mode.c_str());
      std::int64_t begin = from;
      for (const auto& iv : intervals) {
        std::vector<double> lat;
        std::uint64_t lost_iv = 0, nonfinite = 0;
        for (const auto& r : results) {
          for (std::size_t i = 0; i < r.latency_us.size(); ++i)
            if (r.latency_at_ns[i] >= begin && r.latency_at_ns[i] < iv.end_ns) lat.push_back(r.latency_us[i]);
          for (const auto& [t, n] : r.lost_at)
            if (t >= begin && t < iv.end_ns) lost_iv += n;
          nonfinite += r.nonfinite;
        }
        const auto q = neurosim::common::percentiles(lat);
        std::printf("soak,%s,%.0f,%zu,%.1f,%.1f,%.1f,%llu,%ld,%.1f,%llu\n", mode.c_str(),
                    1e-9 * static_cast<double>(iv.end_ns - from), lat.size(), q.p50, q.p99, q.max,
                    static_cast<unsigned long long>(lost_iv), iv.rss_kb, iv.step_p99_us,
                    static_cast<unsigned long long>(nonfinite));
        begin = iv.end_ns;
      }
    }
    const std::size_t samples = all.size();
    const neurosim::common::Percentiles pc = neurosim::common::percentiles(all);
    const double mx = pc.max, p50 = pc.p50, p99 = pc.p99;
    if (o.csv) {
      std::printf("%d,%zu,%.1f,%.1f,%.1f,%llu,%.1f,%d,%s,%s,%.1f,%.1f\n", o.stations, samples, p50, p99, mx,
                  static_cast<unsigned long long>(lost), cpu_pct, load, mode.c_str(), contact.name.c_str(),
                  step_p50_us, step_p99_us);
    } else {
      std::printf("latency_bench: %d station(s), %.1f s on %s (server %s, DDS domain %d), %d busy threads, step mode %s, contact %s\n",
                  o.stations, o.seconds, o.scene.c_str(), o.server.c_str(), domain, load, mode.c_str(),
                  contact.name.c_str());
      std::printf("  ToolStates sent %llu, answered %zu; latency p50 %.1f us, p99 %.1f us, max %.1f us\n",
                  static_cast<unsigned long long>(sent), samples, p50, p99, mx);
      std::printf("  ContactModels lost %llu; server CPU %.1f %% of one core\n", static_cast<unsigned long long>(lost),
                  cpu_pct);
      std::printf("  server (last SimStatus): %s%s\n", step_text.c_str(),
                  o.viewer ? (", viewer matched (Deformation frames pending: " + std::to_string(frames) + ")").c_str() : "");
    }
    std::fflush(stdout);
    if (samples == 0) throw std::runtime_error("no ContactModel answered a ToolState; server log: " + log.string());
  } catch (const std::exception& e) {
    std::cerr << "latency_bench: " << e.what() << "\n";
    rc = 1;
  }
  stop_server();
  }
  return rc;
}
