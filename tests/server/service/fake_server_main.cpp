// service_test_fake_server: neurosim-server's command line running the test-only FakeSimulation
// (tests/server/service/fake_simulation.hpp), for the DDS plumbing tests.
#include "server/service/server.hpp"
#include "tests/server/service/fake_simulation.hpp"

int main(int argc, char** argv) {
  return neurosim::service::run_main(argc, argv, [](const neurosim::scene::Model& model,
                                                      const neurosim::service::ServerOptions&) {
    return neurosim::service::testing::make_fake(model);
  });
}
