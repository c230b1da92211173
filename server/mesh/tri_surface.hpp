// Closed triangle surfaces (rigid obstacles such as the skull): the closedness check that a
// rigid scene mesh must pass at load, and its enclosed volume.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <string>
#include <vector>

namespace neurosim::mesh {

// What check_closed found. A closed surface has every edge shared by exactly two triangles that
// traverse it in opposite directions (a consistently oriented 2-manifold without boundary).
struct ClosedSurfaceReport {
  int triangles{0};
  int edges{0};
  int boundary_edges{0};        // used by one triangle (a hole)
  int nonmanifold_edges{0};     // used by three or more triangles
  int misoriented_edges{0};     // used twice in the same direction (inconsistent orientation)
  int degenerate_triangles{0};  // a repeated vertex or an index out of range
  // Signed enclosed volume, unit m^3 (divergence theorem); > 0 for an outward orientation.
  double volume_m3{0.0};
  std::string first_problem;  // the first bad edge or triangle, for messages ("" when closed)

  bool closed() const {
    return boundary_edges == 0 && nonmanifold_edges == 0 && misoriented_edges == 0 &&
           degenerate_triangles == 0 && triangles > 0;
  }
};

ClosedSurfaceReport check_closed(const std::vector<Vec3>& vertices_m,
                                 const std::vector<Tri>& triangles);

// Throws std::runtime_error("<source>: not a closed, outward-oriented surface: ...") unless the
// surface is closed with a positive enclosed volume.
void require_closed_outward(const std::vector<Vec3>& vertices_m, const std::vector<Tri>& triangles,
                            const std::string& source);

}  // namespace neurosim::mesh
