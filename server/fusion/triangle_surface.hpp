// A closed triangle surface: the embedded mesh B as the inclusion decision sees it (paper 2.5,
// "the set of surface triangles of mesh B").
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::fusion {

using mesh::Tri;
using mesh::Vec3;

struct TriangleSurface {
  std::vector<Vec3> vertices_m;   // unit m; may hold vertices no triangle uses
  std::vector<Tri> triangles;     // indices into vertices_m
  std::string name{"<surface>"};  // for messages

  // B's boundary faces on B's own vertex numbering (TetMesh::surface()).
  static TriangleSurface of(const mesh::TetMesh& mesh, std::string name = {});
};

// An edge used by an odd number of triangles (a hole's rim when the count is 1).
struct OpenEdge {
  int v0{-1};
  int v1{-1};        // v0 < v1, vertex ids of the surface
  int triangles{0};  // how many triangles use it
};

// Edges that make the surface not closed; empty when every edge is used an even number of
// times (the parity inside test needs exactly that).
std::vector<OpenEdge> open_edges(const TriangleSurface& surface);

// Throws std::invalid_argument naming the surface and the offending triangle/vertex/edges:
// empty surface, index out of range, repeated index in a triangle, non-finite vertex, open edges.
void validate_closed(const TriangleSurface& surface);

}  // namespace neurosim::fusion
