// neurosim-viewer: the navigation / observer station. `neurosim-viewer --help` lists the
// options (options.cpp); usage errors exit 2.
#include "common/cli.hpp"
#include "viewer_client/viewer/app.hpp"

#include <signal.h>

#include <atomic>
#include <iostream>

namespace {
std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop.store(true); }
}  // namespace

int main(int argc, char** argv) {
  namespace nv = neurosim::viewer;
  nv::ViewerOptions options;
  try {
    bool help = false;
    options = nv::parse_options(argc, argv, help);
    if (help) return 0;
  } catch (const std::invalid_argument& e) {
    return neurosim::cli::report_usage_error("neurosim-viewer", e.what());
  }
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return nv::run_viewer(options, std::cerr, &g_stop);
}
