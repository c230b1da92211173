// Priority per mesh pair (paper 2.4-2.5 step 1): in an overlap the mesh of higher priority
// (the vessel) keeps its volume and the other (the brain) gets a new boundary around it.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>

namespace neurosim::fusion {

struct PrioritizedMesh {
  const mesh::TetMesh* mesh{nullptr};
  int priority{0};  // scene Mesh.priority: higher wins
  std::string name;
};

struct FusionPair {
  PrioritizedMesh host;      // lower priority: gets the new boundary S'
  PrioritizedMesh embedded;  // higher priority: its closed surface is the cut
};

// Orders the pair by priority. Throws std::invalid_argument for a null mesh, the same mesh
// twice, or equal priorities (the overlap would be ambiguous), naming both meshes.
FusionPair decide_roles(const PrioritizedMesh& first, const PrioritizedMesh& second);

}  // namespace neurosim::fusion
