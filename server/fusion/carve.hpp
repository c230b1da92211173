// Carving a host around its embedded meshes (paper 2.4): the embedded mesh has the higher
// priority and keeps its volume, so the host's tetrahedra enclosed by the new boundary S' are
// removed at load (interaction::Simulation) and S' becomes the host's boundary there. The patient
// model builder runs the same decision before it writes a scene.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <vector>

namespace neurosim::fusion {

// Per tetrahedron of `host`: 1 when it is enclosed by the triangles `cut` (S'), i.e. not
// reachable from the host's surface without crossing a face of S'. All 0 if S' does not close.
std::vector<char> tets_inside(const mesh::TetMesh& host, const std::vector<mesh::Tri>& cut);

}  // namespace neurosim::fusion
