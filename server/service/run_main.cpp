// The neurosim-server command line (server.hpp run_main).
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/fem/tier.hpp"
#include "server/scene/compile.hpp"
#include "server/service/server.hpp"

#include <dlfcn.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
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

}  // namespace

int run_main(int argc, char** argv, const SimulationFactory& factory) {
  ServerOptions opt;
  double duration_s = 0;
  std::string tier_text;  // --tier as given; empty: the scene's effects.tier
  cli::Parser p("neurosim-server",
                "The simulation service: steps the scene and serves haptic stations and viewers "
                "over DDS.");
  p->add_option("--scene", opt.scene_path, "scene file (protobuf text, idl/scene.proto)")
      ->required();
  // Checked with fem::parse_tier (the spelling neurosim-solve --tier takes, any case), so an
  // unknown tier is a usage error (exit 2) before the scene is even read.
  p->add_option("--tier", tier_text,
                "elasticity tier: linear | corotational | nonlinear (default: the scene's "
                "effects.tier)")
      ->check(CLI::Validator(
          [](std::string& value) -> std::string {
            if (fem::parse_tier(value)) return {};
            return "unknown elasticity tier '" + value +
                   "' (expected linear, corotational or nonlinear)";
          },
          "linear|corotational|nonlinear"));
  p->add_option("--duration", duration_s,
                "stop after S seconds (default: run until SIGINT/SIGTERM)")
      ->check(cli::positive());
  p->add_option("--domain", opt.domain,
                "DDS domain id (default: the CYCLONEDDS_URI configuration's)")
      ->check(cli::in_range(0, 230));
  p->add_option("--server-id", opt.server_id, "SimStatus key")->capture_default_str();
  p->add_option("--topic-prefix", opt.topic_prefix,
                "prepend P to every topic name (test isolation)");
  std::string accuracy_table = NEUROSIM_DEFAULT_ACCURACY_TABLE;
  bool accuracy_table_given = false;
  p->add_option_function<std::string>(
       "--accuracy-table",
       [&](const std::string& v) {
         accuracy_table = v;
         accuracy_table_given = true;
       },
       "the tiers' measured force error against strain (accuracy_bench's table; 'none': no "
       "estimate). Default: " NEUROSIM_DEFAULT_ACCURACY_TABLE " when it exists");
  p->footer("CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs).");
  if (auto rc = p.parse(argc, argv)) return *rc;
  single_thread_blas();
  if (accuracy_table == "none") {
    accuracy_table.clear();
  } else if (!accuracy_table_given && !std::filesystem::exists(accuracy_table)) {
    std::cerr << "neurosim-server: note: no accuracy table at " << accuracy_table
              << ": the expected force error is not reported\n";
    accuracy_table.clear();
  }
  opt.accuracy_table = accuracy_table;

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  try {
    const auto t0 = common::Clock::now();
    scene::Model model = scene::load_model(opt.scene_path);
    for (const auto& w : model.warnings) std::cerr << "neurosim-server: warning: " << w << "\n";
    // --tier replaces the scene's tier before anything is built from it: the simulation, the
    // server's start-up line and SimStatus all see the one tier that runs.
    const scene::Tier scene_tier = model.effects.tier;
    if (!tier_text.empty()) {
      model.effects.tier = *fem::parse_tier(tier_text);  // validated by the option's check
      opt.tier_source = "--tier";
    }
    std::cerr << "neurosim-server: tier " << scene::tier_name(model.effects.tier);
    if (tier_text.empty())
      std::cerr << " (from the scene's effects.tier)\n";
    else
      std::cerr << " (from --tier " << tier_text << "; the scene's effects.tier is "
                << scene::tier_name(scene_tier) << ")\n";
    auto sim = factory(model);
    const double build_s = common::seconds_since(t0);
    std::cerr << "neurosim-server: simulation built in " << build_s << " s\n";
    if (g_stop.load()) return 0;
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
