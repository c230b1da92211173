// What the three mesh-reader targets check on a file a reader accepted: the promises of
// server/mesh/io.hpp (indices in range, one label per element, finite coordinates), then
// TetMesh::build and the quality report on it.
#pragma once

#include "fuzz/fuzz_target.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/quality.hpp"

#include <cmath>
#include <stdexcept>

namespace neurosim::fuzz {

inline void check_mesh(mesh::MeshData data) {
  const long long nv = static_cast<long long>(data.vertices_m.size());
  for (const auto& v : data.vertices_m) require(v.allFinite(), "vertices are finite");
  for (const auto& t : data.tets)
    for (int i : t) require(i >= 0 && i < nv, "tetrahedron indices in range");
  for (const auto& t : data.triangles)
    for (int i : t) require(i >= 0 && i < nv, "triangle indices in range");
  require(data.tet_labels.size() == data.tets.size(), "one label per tetrahedron");
  require(data.triangle_labels.size() == data.triangles.size(), "one label per triangle");
  require(!data.tets.empty(), "a mesh read has tetrahedra");
  try {
    const mesh::TetMesh built =
        mesh::TetMesh::build(std::move(data.vertices_m), std::move(data.tets), {});
    require(built.num_tets() > 0, "a built mesh has tetrahedra");
    for (int t = 0; t < static_cast<int>(built.num_tets()); ++t)
      require(built.tet_volume(t) > 0.0, "built tetrahedra have positive volume");
    (void)mesh::quality(built);
  } catch (const std::invalid_argument&) {  // degenerate, repeated vertex, ...: refused, named
  }
}

}  // namespace neurosim::fuzz
