// neurosim-server: the simulation service over DDS (issue 5). See server.hpp for the design.
#include "server/service/server.hpp"

#include <stdexcept>

int main(int argc, char** argv) {
  return neurosim::service::run_main(
      argc, argv,
      [](const neurosim::scene::Scene& scene,
         const std::string& path) -> std::unique_ptr<neurosim::interaction::Simulation> {
#if NEUROSIM_HAVE_INTERACTION
        return neurosim::interaction::Simulation::build(scene, path);
#else
        (void)scene;
        throw std::runtime_error(path + ": this neurosim-server was built without "
                                        "neurosim::interaction (server/interaction): no physics to run");
#endif
      });
}
