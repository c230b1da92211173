// The neurosim-server command line (server.hpp run_main).
#include "server/scene/compile.hpp"
#include "server/service/server.hpp"

#include <dlfcn.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <thread>

namespace neurosim::service {

namespace {

std::atomic<bool> g_stop{false};
static_assert(std::atomic<bool>::is_always_lock_free, "the signal handler needs a lock-free flag");

extern "C" void on_signal(int) { g_stop.store(true); }

void usage(std::ostream& os) {
  os << "usage: neurosim-server --scene FILE [--duration SECONDS] [--domain ID]\n"
        "                       [--server-id NAME] [--topic-prefix PREFIX]\n"
        "  --scene FILE       scene file (protobuf text, idl/scene.proto)\n"
        "  --duration S       stop after S seconds (default: run until SIGINT/SIGTERM)\n"
        "  --domain ID        DDS domain id (default: the CYCLONEDDS_URI configuration's)\n"
        "  --server-id NAME   SimStatus key (default neurosim-server)\n"
        "  --topic-prefix P   prepend P to every topic name (test isolation)\n"
        "CYCLONEDDS_URI must be set (deploy/cyclonedds/loopback.xml for local runs).\n";
}

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
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](const char* name) -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(std::string(name) + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "--scene") {
        opt.scene_path = value("--scene");
      } else if (a == "--duration") {
        const std::string v = value("--duration");
        std::size_t used = 0;
        duration_s = std::stod(v, &used);
        if (used != v.size() || !std::isfinite(duration_s) || duration_s <= 0)
          throw std::invalid_argument("--duration: '" + v + "' is not a positive number of seconds");
      } else if (a == "--domain") {
        const std::string v = value("--domain");
        std::size_t used = 0;
        const int d = std::stoi(v, &used);
        if (used != v.size() || d < 0 || d > 230)
          throw std::invalid_argument("--domain: '" + v + "' is not a domain id in [0, 230]");
        opt.domain = d;
      } else if (a == "--server-id") {
        opt.server_id = value("--server-id");
      } else if (a == "--topic-prefix") {
        opt.topic_prefix = value("--topic-prefix");
      } else if (a == "-h" || a == "--help") {
        usage(std::cout);
        return 0;
      } else {
        throw std::invalid_argument("unknown argument '" + a + "'");
      }
    } catch (const std::exception& e) {
      std::cerr << "neurosim-server: " << e.what() << "\n";
      usage(std::cerr);
      return 2;
    }
  }
  if (opt.scene_path.empty()) {
    std::cerr << "neurosim-server: --scene is required\n";
    usage(std::cerr);
    return 2;
  }
  single_thread_blas();

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  try {
    const auto t0 = std::chrono::steady_clock::now();
    const scene::Model model = scene::load_model(opt.scene_path);
    auto sim = factory(model);
    const double build_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::cerr << "neurosim-server: simulation built in " << build_s << " s\n";
    if (g_stop.load()) return 0;
    Server server(model, std::move(sim), opt, std::cerr);
    server.start();
    const auto started = std::chrono::steady_clock::now();
    // Polled: the signal handler only sets a flag; stop() runs here on a normal thread.
    while (!g_stop.load() && server.running()) {
      if (duration_s > 0 &&
          std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() >= duration_s)
        break;
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
