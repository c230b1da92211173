// Coupling map between the new boundary S' of the host and the embedded surface (paper 2.6:
// "colliding boundary nodes"): closest points both ways, with barycentric weights. The
// distances bound the geometric error of tying the two meshes together.
#pragma once

#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_surface.hpp"

#include <array>
#include <vector>

namespace neurosim::fusion {

struct SurfacePoint {
  int triangle{-1};                 // index into the target's triangle list
  std::array<double, 3> weights{};  // barycentric, >= 0, sum 1, on the triangle's vertices
  Vec3 point_m{Vec3::Zero()};       // closest point, unit m
  double distance_m{0.0};           // |node - point|, unit m
};

struct DistanceSummary {
  double max_m{0.0};   // unit m
  double mean_m{0.0};  // unit m
  int argmax{-1};      // index into the node list with the largest distance
};

struct CouplingMap {
  // B's surface vertices (B's ids, ascending) and their closest points on S'
  // (triangle = index into NewBoundary::triangles, weights on A's vertices).
  std::vector<int> embedded_nodes;
  std::vector<SurfacePoint> embedded_on_boundary;
  // S' vertices (A's ids, ascending) and their closest points on B's surface
  // (triangle = index into TriangleSurface::triangles).
  std::vector<int> boundary_nodes;
  std::vector<SurfacePoint> boundary_on_embedded;
  DistanceSummary embedded_to_boundary;
  DistanceSummary boundary_to_embedded;
};

// host_vertices_m: A's vertex positions (rest or current), unit m. Throws std::invalid_argument
// if S' is empty (nothing to couple to) or an index is out of range.
CouplingMap build_coupling_map(const std::vector<Vec3>& host_vertices_m,
                               const NewBoundary& boundary, const TriangleSurface& embedded);

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection 5.1.5), with its
// barycentric weights; triangle index left at -1.
SurfacePoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

}  // namespace neurosim::fusion
