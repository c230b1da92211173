// neurosim-web: the read-only web observer. `neurosim-web --help` lists the options
// (options.cpp); usage errors exit 2, a failure to start (page, DDS, address) exits 1.
#include "common/clock.hpp"
#include "web/bridge.hpp"
#include "web/options.hpp"

#include <malloc.h>
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <mutex>
#include <thread>

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }
}  // namespace

int main(int argc, char** argv) {
  namespace web = neurosim::web;
  web::WebOptions options;
  if (const auto rc = web::parse_command_line(argc, argv, options)) return *rc;
  // Memory that levels off (bench/RESULTS.md "client_soak"), set before any thread starts: one
  // malloc arena for the observer's threads (Cyclone's, CivetWeb's and the senders' buffers are
  // allocated on one thread and freed on another), and a fixed mmap threshold of 64 KiB, so
  // Cyclone's receive buffers (dds_source.cpp: 256 KiB) are mapped and given back when released
  // rather than left resident in the heap once glibc's dynamic threshold has risen above them.
  // MALLOC_ARENA_MAX and MALLOC_MMAP_THRESHOLD_ in the environment take precedence.
  if (std::getenv("MALLOC_ARENA_MAX") == nullptr) mallopt(M_ARENA_MAX, 1);
  if (std::getenv("MALLOC_MMAP_THRESHOLD_") == nullptr) mallopt(M_MMAP_THRESHOLD, 64 * 1024);
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);  // a browser that goes away must not end the bridge

  std::mutex log_m;
  auto log = [&log_m](const std::string& line) {
    std::lock_guard<std::mutex> lk(log_m);
    std::cerr << line << std::endl;
  };
  try {
    web::Bridge bridge(options.bridge, *options.token, log);
    // One line to find the address by (tests and deploy/demo read it); the token is not printed.
    log("neurosim-web: listening on http://" + options.bridge.http.address + ":" +
        std::to_string(bridge.port()) + "/ (open it with ?token=TOKEN; at most " +
        std::to_string(options.bridge.max_clients) + " clients; DDS topic prefix '" +
        options.bridge.dds.topic_prefix + "')");
    const auto t0 = neurosim::common::Clock::now();
    while (!g_stop.load() &&
           (options.duration_s <= 0 || neurosim::common::seconds_since(t0) < options.duration_s))
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    log(std::string("neurosim-web: stopping (") + (g_stop.load() ? "signal" : "--duration") + ")");
  } catch (const std::exception& e) {
    log(std::string("neurosim-web: ") + e.what());
    return 1;
  }
  log("neurosim-web: stopped");
  return 0;
}
