// neurosim-server: the simulation service over DDS (see server.hpp for the design).
#include "server/interaction/simulation.hpp"
#include "server/service/server.hpp"

int main(int argc, char** argv) {
  return neurosim::service::run_main(argc, argv, [](const neurosim::scene::Model& model) {
    return neurosim::interaction::Simulation::build(model);
  });
}
