// service_test_fake_server: neurosim-server's command line running the test-only FakeSimulation
// (tests/server/service/fake_simulation.hpp), for the DDS plumbing tests.
// NEUROSIM_FAKE_BUILD_DELAY_S=S: the build takes S seconds longer (SIGTERM during the load).
#include "server/service/server.hpp"
#include "tests/server/service/fake_simulation.hpp"

#include <chrono>
#include <cstdlib>
#include <thread>

int main(int argc, char** argv) {
  return neurosim::service::run_main(argc, argv, [](const neurosim::scene::Model& model) {
    // Test-only: NEUROSIM_FAKE_BUILD_DELAY_S=S makes the build take S seconds (a slow load, for
    // the SIGTERM-during-load test).
    if (const char* d = std::getenv("NEUROSIM_FAKE_BUILD_DELAY_S"))
      std::this_thread::sleep_for(std::chrono::duration<double>(std::atof(d)));
    return neurosim::service::testing::make_fake(model);
  });
}
