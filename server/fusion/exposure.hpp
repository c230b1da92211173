// Exposure of an embedded mesh: its surface nodes that lie outside its host. The inclusion
// flag per node tells the simulation which surface nodes of B may be tied to S' (the ones inside
// A: an exposed node's closest point of S' may be far away, at the rim where B leaves A); the
// simulation still refuses tool contact with an exposed embedded mesh (it has no contact rows).
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <vector>

namespace neurosim::fusion {

struct ExposureOptions {
  // A node counts as outside when it is outside A's closed surface by more than this distance
  // (unit m): nodes on A's boundary (meshed separately, so a little off it) are inside.
  double tolerance_m{0.0};
};

struct Exposure {
  int surface_nodes{0};        // B's surface vertices checked
  int nodes_outside{0};        // of them, outside A by more than the tolerance
  double max_distance_m{0.0};  // the farthest one's distance to A's surface, unit m
  int farthest_node{-1};       // its vertex id in B (-1: none outside)
  // Per vertex of B: 1 for a surface node outside A by more than the tolerance, 0 otherwise
  // (interior nodes included), so nodes_outside == count of 1s.
  std::vector<char> outside;
};

// Throws std::invalid_argument if A's surface is not closed (TriangleSurface checks).
Exposure embedded_outside_host(const mesh::TetMesh& host, const mesh::TetMesh& embedded,
                               const ExposureOptions& options = {});

}  // namespace neurosim::fusion
