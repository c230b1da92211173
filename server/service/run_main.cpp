// The neurosim-server command line (server.hpp run_main).
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/load_watch.hpp"
#include "server/fem/element.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/fem/tier.hpp"
#include "server/scene/compile.hpp"
#include "server/service/server.hpp"

#include <dlfcn.h>
#include <malloc.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <optional>
#include <iostream>
#include <string>
#include <thread>

namespace neurosim::service {

namespace {

namespace cli = neurosim::cli;

std::atomic<bool> g_stop{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void on_signal(int) { g_stop.store(true); }

// One BLAS thread: the step thread must not compete with BLAS worker threads for 2 cores.
// OpenBLAS reads OPENBLAS_NUM_THREADS when it is loaded (before main), so also tell it directly.
void single_thread_blas() {
  setenv("OPENBLAS_NUM_THREADS", "1", 0);
  using SetThreads = void (*)(int);
  if (auto* f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads")))
    f(1);
}

// One malloc arena for the whole process (unless MALLOC_ARENA_MAX says otherwise). Cyclone DDS
// allocates per sample on its receive and write paths in different threads, and glibc's
// per-thread arenas then keep growing the resident set though the heap in use is flat: with 4
// stations at 1 kHz the server's RSS grew ~285 kB per minute (heap in use, heaptrack: flat
// after the first 90 s); with one arena it stays flat, 4.6 MB smaller, at the same latency
// (bench/RESULTS.md, "Soak"). Called before any thread starts.
void one_malloc_arena() {
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 1);
}

}  // namespace

int run_main(int argc, char** argv, const SimulationFactory& factory) {
  ServerOptions opt;
  double duration_s = 0;
  std::string tier_text;  // --tier as given; empty: the scene's effects.tier
  std::string element_text;  // --element as given; empty: the scene's material.element
  cli::Parser p("neurosim-server",
                "The simulation service: steps the scene and serves haptic stations and viewers "
                "over DDS.");
  p.add_option("--scene", opt.scene_path, "scene file (protobuf text, idl/scene.proto)")
      ->required();
  // Checked with fem::parse_tier (the spelling neurosim-solve --tier takes, any case), so an
  // unknown tier is a usage error (exit 2) before the scene is even read.
  p.add_option("--tier", tier_text,
               "elasticity tier: linear | nonlinear (default: the scene's "
               "effects.tier)")
      ->check(cli::Check(
          [](std::string& value) -> std::string {
            const auto tier = fem::parse_tier(value);
            if (tier && fem::tier_served(*tier)) return {};
            if (tier) return std::string(fem::kCorotationalWithdrawn);
            return "unknown elasticity tier '" + value + "' (expected linear or nonlinear)";
          },
          "linear|nonlinear"));
  p.add_option(
       "--element", element_text,
       "element: smoothed-tet | anp-tet | linear-tet (default: the scene's material.element)")
      ->check(cli::Check(
          [](std::string& value) -> std::string {
            if (fem::parse_element(value)) return {};
            return "unknown element '" + value + "' (expected " + fem::element_names() + ")";
          },
          "smoothed-tet|anp-tet|linear-tet"));
  p.add_option("--duration", duration_s,
               "stop after S seconds of serving (default: run until SIGINT/SIGTERM)")
      ->check(cli::positive());
  double load_timeout_s = 900;
  p.add_option("--load-timeout", load_timeout_s,
               "give up (exit 1, naming the phase) when loading the scene and building the "
               "simulation take longer than S seconds; 0: no limit")
      ->capture_default_str()
      ->check(cli::range(0.0, 1e6));
  p.add_option("--domain", opt.domain,
               "DDS domain id (default: the CYCLONEDDS_URI configuration's)")
      ->check(cli::in_range(0, 230));
  p.add_option("--server-id", opt.server_id, "SimStatus key")->capture_default_str();
  p.add_option("--topic-prefix", opt.topic_prefix,
               "prepend P to every topic name (test isolation)");
  std::string accuracy_table = NEUROSIM_DEFAULT_ACCURACY_TABLE;
  bool accuracy_table_given = false;
  p.add_option_function<std::string>(
      "--accuracy-table",
      [&](const std::string& v) {
        accuracy_table = v;
        accuracy_table_given = true;
      },
      "the tiers' measured force error against strain (accuracy_bench's table; 'none': no "
      "estimate). Default: " NEUROSIM_DEFAULT_ACCURACY_TABLE " when it exists");
  std::string disc_table = NEUROSIM_DEFAULT_DISCRETIZATION_TABLE;
  bool disc_table_given = false;
  p.add_option_function<std::string>(
      "--discretization-table",
      [&](const std::string& v) {
        disc_table = v;
        disc_table_given = true;
      },
      "the hosts' measured discretization error against the converged answer (nested "
      "refinements extrapolated: press_refinement_bench's and accuracy_bench's table; 'none': "
      "unknown). Default: " NEUROSIM_DEFAULT_DISCRETIZATION_TABLE
      " when it exists");
  p.add_option("--station-idle-timeout", opt.station_idle_timeout_s,
               "a station that sends no ToolState for S seconds loses its slot (and its writer "
               "its binding to the station id)")
      ->capture_default_str()
      ->check(cli::range(0.05, 3600.0));
  p.add_option("--max-stations-per-participant", opt.max_stations_per_participant,
               "stations one DDS participant may hold at once")
      ->capture_default_str()
      ->check(cli::range(1, 64));
  p.add_option("--workspace-margin", opt.workspace_margin_m,
               "tool tips further than M metres outside the scene's bounding box are rejected")
      ->capture_default_str()
      ->check(cli::range(0.0, 100.0));
  p.add_option("--log-lines-per-second", opt.log_lines_per_second,
               "log lines per second per cause (joins, refusals, each rejection cause); the rest "
               "is summarised")
      ->capture_default_str()
      ->check(cli::range(1, 1000));
  std::string step_mode = "event", rt_priority, rt_cpus;
  p.add_option("--step-mode", step_mode,
               "event: a step when a ToolState arrives (at most --max-step-rate-factor x the "
               "scene rate; one period after the last step when none does); clock: one step per "
               "period on the free-running clock")
      ->check(cli::one_of({"event", "clock"}))
      ->capture_default_str();
  p.add_option("--max-step-rate-factor", opt.max_step_rate_factor,
               "event step mode: at most this many times rates.step_hz")
      ->capture_default_str()
      ->check(cli::range(1.0, 100.0));
  p.add_option("--rt-priority", rt_priority,
               "thread priorities, ROLE=P,... (roles step, dds, field; P 1..99 SCHED_FIFO, 0 "
               "normal; default " +
                   opt.threads.priorities_text() +
                   "); refused priorities are logged, "
                   "the server runs anyway");
  p.add_option("--cache-dir", opt.cache_dir,
               "disk cache of the hosts' factors and boundary operators, keyed by their "
               "content: a second start of the same scene reads them instead of factoring "
               "(default: none)");
  p.add_option("--rt-cpus", rt_cpus,
               "CPU sets, ROLE=CPUS,... (CPUS: numbers and ranges joined by '+', e.g. "
               "step=1,dds=0,field=0-1; default: any CPU)");
  p.add_flag_function(
      "--barycentric-contact", [&](std::int64_t) { opt.contact.barycentric = true; },
      "contact rows without the spread: contact spread 0, no smooth normals, no near field "
      "(as interaction_bench --barycentric-contact); default: the library's contact options");
  p.add_option_function<double>(
       "--contact-spread", [&](const double& v) { opt.contact.spread = v; },
       "SimulationOptions::contact_spread, [0, 4] (0 needs --contact-near-field off); default: "
       "the library's")
      ->check(cli::range(0.0, 4.0));
  p.add_option_function<std::string>(
       "--contact-smooth-normals",
       [&](const std::string& v) { opt.contact.smooth_normals = v == "on"; },
       "SimulationOptions::contact_smooth_normals, on|off; default: the library's")
      ->check(cli::one_of({"on", "off"}));
  p.add_option_function<std::string>(
       "--contact-near-field", [&](const std::string& v) { opt.contact.near_field = v == "on"; },
       "SimulationOptions::contact_near_field, on|off (on needs a contact spread > 0); default: "
       "the library's")
      ->check(cli::one_of({"on", "off"}));
  p.add_option_function<int>(
       "--contact-max-rows", [&](const int& v) { opt.contact.max_rows = v; },
       "SimulationOptions::max_contact_nodes_per_tool, [1, 100000]: a tool's deepest rows kept "
       "(a patch of cells much finer than the tip needs more; the rest are counted in "
       "SimStatus.steps_with_rows_dropped); default: the library's")
      ->check(cli::range(1, 100000));
  p.add_option_function<int>(
       "--lcp-max-iterations", [&](const int& v) { opt.contact.lcp_max_iterations = v; },
       "SimulationOptions::lcp_max_iterations, [1, 1000000]: the contact LCP's pivots (about one "
       "per active row; a step that runs out keeps the last good answer, counted in "
       "SimStatus.steps_not_converged); default: the library's")
      ->check(cli::range(1, 1000000));
  p.footer("CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs).");
  if (auto rc = p.parse(argc, argv)) return *rc;
  opt.step_mode = step_mode == "clock" ? StepMode::kClock : StepMode::kEvent;
  try {
    opt.contact.validate();
    common::apply_priorities(opt.threads, rt_priority, "--rt-priority");
    common::apply_cpus(opt.threads, rt_cpus, "--rt-cpus");
  } catch (const std::invalid_argument& e) {
    std::cerr << "neurosim-server: " << e.what() << "\n";
    return 2;
  }
  single_thread_blas();
  one_malloc_arena();
  if (accuracy_table == "none") {
    accuracy_table.clear();
  } else if (!accuracy_table_given && !std::filesystem::exists(accuracy_table)) {
    std::cerr << "neurosim-server: note: no accuracy table at " << accuracy_table
              << ": the expected force error is not reported\n";
    accuracy_table.clear();
  }
  opt.accuracy_table = accuracy_table;
  if (disc_table == "none") {
    disc_table.clear();
  } else if (!disc_table_given && !std::filesystem::exists(disc_table)) {
    std::cerr << "neurosim-server: note: no discretization table at " << disc_table
              << ": the total error estimate is unknown\n";
    disc_table.clear();
  }
  opt.discretization_table = disc_table;

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  // Load phases run on a worker thread while this thread watches the signal flag and the load
  // time: a signal during a long load (mesh generation, compliance precompute, inclusion
  // decision) ends the process within ~0.1 s instead of after the load, and so does a load
  // that passes --load-timeout (a blocked read, a mesh far too large for this machine).
  common::LoadWatchDef watch_def;
  watch_def.program = "neurosim-server";
  watch_def.limit_s = load_timeout_s;
  watch_def.stop = &g_stop;
  watch_def.on_stop = "exiting without serving";
  common::LoadWatch watch(watch_def);

  try {
    const auto t0 = common::Clock::now();
    scene::Model model =
        watch.run("loading the scene " + opt.scene_path, [&] { return scene::load_model(opt.scene_path); });
    for (const auto& w : model.warnings) std::cerr << "neurosim-server: warning: " << w << "\n";
    // Scene features this server does not run yet: refused, never ignored.
    // Rigid meshes (the skull) are obstacles for the tools (Server: a tool proxy per station,
    // ContactModel.rigid_planes). Per-tissue materials: the interactive simulation runs one
    // material per mesh, so a tissue whose own material has the mesh's E and nu (the same
    // physics) is accepted and any other refused, never run with the mesh's values.
    for (const auto& m : model.meshes)
      if (const scene::TissueDef* t = m.tissue_with_other_material())
        throw std::runtime_error(
            opt.scene_path + ": mesh \"" + m.id + "\", tissue \"" + t->name + "\": material \"" +
            t->material.name + "\" (E " + std::to_string(t->material.youngs_modulus_pa) +
            " Pa, nu " + std::to_string(t->material.poisson_ratio) + ") differs from the mesh's \"" +
            m.material.name + "\": per-tissue materials are not implemented in the interactive "
            "server (neurosim-solve uses them on uncoupled meshes)");
    // --tier replaces the scene's tier before anything is built from it: the simulation, the
    // server's start-up line and SimStatus all see the one tier that runs.
    const scene::Tier scene_tier = model.effects.tier;
    if (!element_text.empty()) model.set_element(*fem::parse_element(element_text));
    if (!tier_text.empty()) {
      model.effects.tier = *fem::parse_tier(tier_text);  // validated by the option's check
      opt.tier_source = "--tier";
    }
    std::cerr << "neurosim-server: contact options: " << opt.contact.describe() << "\n";
    std::cerr << "neurosim-server: tier " << scene::tier_name(model.effects.tier);
    if (tier_text.empty())
      std::cerr << " (from the scene's effects.tier)\n";
    else
      std::cerr << " (from --tier " << tier_text << "; the scene's effects.tier is "
                << scene::tier_name(scene_tier) << ")\n";
    auto sim = watch.run("building the simulation of " + opt.scene_path +
                             " (meshes, compliance, inclusion decision)",
                         [&] { return factory(model, opt); });
    const double build_s = common::seconds_since(t0);
    std::cerr << "neurosim-server: simulation built in " << build_s << " s\n";
    if (g_stop.load()) {
      std::cerr << "neurosim-server: signal received after the build: exiting without serving\n";
      return 0;
    }
    Server server(model, std::move(sim), opt, std::cerr);
    server.start();
    const auto started = common::Clock::now();
    // Polled: the signal handler only sets a flag; stop() runs here on a normal thread.
    while (!g_stop.load() && server.running()) {
      if (duration_s > 0 && common::seconds_since(started) >= duration_s) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (g_stop.load()) std::cerr << "neurosim-server: signal received, shutting down\n";
    server.stop();
    const std::string err = server.error();
    if (!err.empty()) {
      std::cerr << "neurosim-server: " << err << "\n";
      return 1;
    }
  } catch (const std::exception& e) {
    std::cerr << "neurosim-server: " << e.what() << "\n";
    return 1;
  }
  return 0;
}

}  // namespace neurosim::service
