#include "server/fusion/priority.hpp"

#include <stdexcept>

namespace neurosim::fusion {

FusionPair decide_roles(const PrioritizedMesh& first, const PrioritizedMesh& second) {
  const std::string pair = "meshes '" + first.name + "' and '" + second.name + "'";
  if (first.mesh == nullptr || second.mesh == nullptr) {
    throw std::invalid_argument("fusion pair " + pair + ": a mesh is missing");
  }
  if (first.mesh == second.mesh) {
    throw std::invalid_argument("fusion pair " + pair + ": a mesh cannot overlap itself");
  }
  if (first.priority == second.priority) {
    throw std::invalid_argument("fusion pair " + pair + ": equal priority " +
                                std::to_string(first.priority) +
                                "; give the embedded mesh (e.g. the vessel) the higher priority");
  }
  if (first.priority > second.priority) return {second, first};
  return {first, second};
}

}  // namespace neurosim::fusion
