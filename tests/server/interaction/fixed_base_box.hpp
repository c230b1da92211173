// A box [0, edge]^3 m meshed at a cell size with its base (z = 0) fixed: the smallest host the
// interaction tests build bodies, operators and workers on.
#pragma once

#include "server/mesh/generate.hpp"

#include <vector>

namespace neurosim::interaction::fixtures {

struct FixedBaseBox {
  mesh::TetMesh mesh;
  std::vector<int> fixed;  // the vertices at z = 0
};

inline FixedBaseBox fixed_base_box(double cell_size_m, double edge_m = 0.04) {
  mesh::MeshingOptions o;
  o.cell_size_m = cell_size_m;
  o.seed = 1;
  FixedBaseBox b;
  b.mesh = mesh::generate_box({0, 0, 0}, {edge_m, edge_m, edge_m}, o).mesh;
  for (std::size_t v = 0; v < b.mesh.num_vertices(); ++v)
    if (b.mesh.vertices()[v].z() < 1e-9) b.fixed.push_back(static_cast<int>(v));
  return b;
}

}  // namespace neurosim::interaction::fixtures
