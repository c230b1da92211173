// Exposure of an embedded mesh: its surface nodes that lie outside its host. The inclusion
// decision only carves the host where the embedded surface is inside it, and the tie holds every
// embedded surface node to its closest point of S'; a part of B that sticks out of A is neither
// carved around nor contactable. The simulation refuses such a scene when a tool touches tissue.
#pragma once

#include "server/mesh/tet_mesh.hpp"

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
};

// Throws std::invalid_argument if A's surface is not closed (TriangleSurface checks).
Exposure embedded_outside_host(const mesh::TetMesh& host, const mesh::TetMesh& embedded,
                               const ExposureOptions& options = {});

}  // namespace neurosim::fusion
