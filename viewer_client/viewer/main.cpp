// neurosim-viewer: the navigation / observer station. See options.cpp for the usage.
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
    if (help) {
      std::cout << nv::usage();
      return 0;
    }
  } catch (const std::exception& e) {
    std::cerr << "neurosim-viewer: " << e.what() << "\n" << nv::usage();
    return 2;
  }
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  return nv::run_viewer(options, std::cerr, &g_stop);
}
