// The contactable surface of a body: the host's outer surface triangles (every vertex a contact
// node or a fixed node), their edge and vertex incidence, and a uniform grid over them for the
// candidates near a tool; and the closest point of a triangle to a point, with its feature
// (face, edge or vertex) and barycentric weights (Ericson, Real-Time Collision Detection 5.1.5).
#pragma once

#include "server/interaction/tool_geometry.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <array>
#include <cstdint>
#include <vector>

namespace neurosim::interaction {

enum class TriangleFeature : std::uint8_t { kVertex, kEdge, kFace };

// Closest point of a triangle (p[0], p[1], p[2]) to x: the point (unit m), its barycentric
// weights, the feature it lies in; for a vertex `a` is its local index, for an edge the edge runs
// from local vertex a to (a + 1) % 3.
struct TrianglePoint {
  mesh::Vec3 point_m{mesh::Vec3::Zero()};
  std::array<double, 3> weights{};
  TriangleFeature feature{TriangleFeature::kFace};
  int a{0};
};
TrianglePoint closest_on_triangle(const mesh::Vec3& x, const std::array<mesh::Vec3, 3>& p);

// One contactable triangle: host node ids (outward orientation), their contact slots (-1: a fixed
// node, which never moves), and per edge k (local vertices k, k+1) the number of contactable
// triangles that share it.
struct SurfaceTriangle {
  std::array<int, 3> node{};
  std::array<int, 3> slot{};
  std::array<int, 3> edge_triangles{};
};

struct ContactSurfaceDefinition {
  const mesh::TetMesh* host{nullptr};
  const std::vector<int>* contact_slot{nullptr};  // per host node: contact slot or -1
  const std::vector<int>* fixed_nodes{nullptr};   // sorted host node ids
};

class ContactSurface {
 public:
  ContactSurface() = default;
  explicit ContactSurface(const ContactSurfaceDefinition& def);

  const std::vector<SurfaceTriangle>& triangles() const { return triangles_; }
  // Appends the triangles whose rest bounding sphere may reach the box [lo, hi] (a superset).
  void query(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const;
  // Rest centroid and the largest centroid-vertex distance over all triangles, unit m.
  const mesh::Vec3& centroid(int t) const { return centroid_[t]; }
  // Largest centroid-vertex distance of triangle t (rest), unit m.
  double radius_m(int t) const { return radius_m_[t]; }
  double max_radius_m() const { return max_radius_m_; }
  double mean_edge_m() const { return mean_edge_m_; }

 private:
  std::vector<SurfaceTriangle> triangles_;
  std::vector<mesh::Vec3> centroid_;
  std::vector<double> radius_m_;
  PointGrid grid_;
  double max_radius_m_{0.0};
  double mean_edge_m_{0.0};
};

}  // namespace neurosim::interaction
