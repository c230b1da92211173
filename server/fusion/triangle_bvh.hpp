// A bounding-volume hierarchy over a constant triangle surface (CGAL's AABB tree, built once):
// the triangles near a box and the closest point of the surface, for rigid obstacles (the skull)
// against the tool. Queries allocate nothing once the caller's output vector has its capacity.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <memory>
#include <vector>

namespace neurosim::fusion {

struct ClosestTriangle {
  int triangle{-1};
  mesh::Vec3 point_m{mesh::Vec3::Zero()};
  double distance_m{0.0};
};

class TriangleBvh {
 public:
  // Throws std::invalid_argument for no triangles or a vertex index out of range.
  TriangleBvh(const std::vector<mesh::Vec3>& vertices_m, const std::vector<mesh::Tri>& triangles);
  ~TriangleBvh();
  TriangleBvh(TriangleBvh&&) noexcept;
  TriangleBvh& operator=(TriangleBvh&&) noexcept;

  // Appends the index of every triangle that meets the box [lo, hi] (unit m) to `out`.
  void triangles_in_box(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const;
  // The closest point of the whole surface to p.
  ClosestTriangle closest(const mesh::Vec3& p) const;
  int size() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace neurosim::fusion
