// Supports of a tetrahedral mesh: its connected parts (nodes joined by tetrahedra) and which of
// them the fixed nodes do not hold. A part needs at least 3 non-collinear fixed nodes, else its
// stiffness has rigid-body modes and no factorization exists (StaticSolver refuses it; the
// patient model builder pins such parts before writing a scene).
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::fem {

// Part id per node (nodes of no tetrahedron get a part of their own); num_parts set.
std::vector<int> connected_parts(const mesh::TetMesh& mesh, int& num_parts);

// What joins tetrahedra into one part. kNode: a shared node (what StaticSolver checks: a part
// with fewer supports is certainly singular). kFace: a shared face; a part hanging on the rest
// by one node or one edge turns about it (a mechanism the node rule does not see). A part is
// held by its fixed nodes and by the nodes it shares with parts already held.
enum class Joint { kNode, kFace };

struct UnsupportedPart {
  int part{-1};
  std::vector<int> nodes;  // ascending, nodes of tetrahedra only
  int fixed{0};            // fixed nodes among them
  std::string problem;     // "has no fixed node (6 rigid-body modes)", ...
};

// The parts with tetrahedra that the fixed nodes leave free to move as a rigid body, in part
// order (UnsupportedPart::problem names what its own fixed nodes leave free). `fixed_nodes` must be in range (unchecked here).
std::vector<UnsupportedPart> unsupported_parts(const mesh::TetMesh& mesh,
                                               const std::vector<int>& fixed_nodes,
                                               Joint joint = Joint::kNode);

}  // namespace neurosim::fem
