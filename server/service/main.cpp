// neurosim-server: the simulation service over DDS (see server.hpp for the design).
#include "server/interaction/simulation.hpp"
#include "server/service/server.hpp"

int main(int argc, char** argv) {
  return neurosim::service::run_main(argc, argv, [](const neurosim::scene::Model& model,
                                                      const neurosim::service::ServerOptions& server) {
    // The live server's mode: compliance columns are solved by a worker ahead of the tools, never
    // inside the step (neurosim-replay and the tests solve them in the step: deterministic).
    neurosim::interaction::SimulationOptions options;
    options.column_worker = true;
    options.compliance_cache_dir = server.cache_dir;
    server.contact.apply(options);  // --barycentric-contact, --contact-spread, ... (validated)
    return neurosim::interaction::Simulation::build(model, options);
  });
}
