// Carving a host around its embedded meshes (paper 2.4): the embedded mesh has the higher
// priority and keeps its volume, so the host's tetrahedra enclosed by the new boundary S' are
// removed at load (interaction::Simulation) and S' becomes the host's boundary there. The patient
// model builder runs the same decision before it writes a scene.
#pragma once

#include "server/fusion/inclusion.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <vector>

namespace neurosim::fusion {

// Per tetrahedron of `host`: 1 when it lies on B's side of S', i.e. reachable from a tetrahedron
// that contributed a face of S' (NewBoundary::source_tet: it meets B's surface) without crossing
// a face of S'. Every face between that region and the rest of the host is a face of S', so the
// flood never leaks; it also carves where B crosses the host's surface (S' open there), which a
// flood from the host's surface could not (it reaches everything). For an S' that encloses B it
// gives the tetrahedra not reachable from the host's surface, as long as no host tetrahedra lie
// in a cavity of B. Empty S': nothing.
std::vector<char> tets_inside(const mesh::TetMesh& host, const NewBoundary& cut);

}  // namespace neurosim::fusion
