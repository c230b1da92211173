// Parts of the host mesh that the server would load free to move as rigid bodies: the host is
// carved around its embedded meshes at load (fusion::tets_inside, as interaction::Simulation
// does), then every part of what is left (tetrahedra joined through faces: a part hanging on the
// rest by one node or edge would turn about it) needs >= 3 non-collinear fixed nodes
// (fem::unsupported_parts with Joint::kFace; the solvers refuse the singular stiffness). A fine brain carved around the artery can
// leave a few nodes cut off; the builder finds them before it writes a scene and pins them, so
// that it never writes a scene that does not load.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::model {

struct IslandReport {
  int carved_tets{0};              // host tetrahedra the load removes (inside S')
  std::vector<int> part_nodes;     // per unsupported part: its node count
  std::vector<int> pinned_nodes;   // ascending host node ids (the loaded mesh's numbering)
};

// `host`: the host as loaded (scene::load_mesh); `fixed_nodes`: its fixed nodes as loaded;
// `embedded`: the meshes coupled to it (empty: no carving). Throws std::runtime_error, naming
// the part, when an unsupported part holds more than `max_fraction` of the host's nodes (not an
// island: the scene's supports are wrong).
IslandReport find_islands(const mesh::TetMesh& host, const std::vector<int>& fixed_nodes,
                          const std::vector<const mesh::TetMesh*>& embedded,
                          const std::string& what, double max_fraction = 0.05);

}  // namespace neurosim::model
