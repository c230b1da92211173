// neurosim-web: the read-only web observer. `neurosim-web --help` lists the options
// (options.cpp); usage errors exit 2, a failure to start (page, DDS, address) exits 1.
#include "common/clock.hpp"
#include "web/bridge.hpp"
#include "web/options.hpp"

#include <signal.h>

#include <atomic>
#include <chrono>
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
