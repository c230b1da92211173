// Rigid obstacles (a scene's `rigid` meshes, e.g. the skull) against the tool: a constant model
// built once from the scene's RigidSurfaces (one BVH over all their triangles), and a query that
// turns the surface points near the tool (tip sphere and shaft capsule) into at most
// kMaxObstaclePlanes constraint planes for the tool tip: n . (x_tip - p) >= 0 keeps the tool part
// that made the plane clear of the bone at the tool's current orientation. The query allocates
// nothing once its Scratch is warm. Never part of the FEM solve.
#pragma once

#include "server/interaction/tool_geometry.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "server/model/rigid.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace neurosim::fusion {
class TriangleBvh;  // server/fusion/triangle_bvh.hpp
}

namespace neurosim::interaction {

inline constexpr int kMaxObstaclePlanes = 8;  // ContactModel.rigid_planes holds at most 8

// One constraint plane in tool-tip space (the configuration space of the tip centre): the tool
// part (tip sphere, or a shaft point at distance shaft_offset_m from the tip along the axis) is
// clear of the obstacle while n . (x_tip - point_m) >= 0. point_m = surface point + radius x n
// - shaft_offset_m x axis.
struct ObstaclePlane {
  mesh::Vec3 point_m{mesh::Vec3::Zero()};    // unit m
  mesh::Vec3 normal{mesh::Vec3::Zero()};     // unit, out of the bone into free space
  mesh::Vec3 surface_point_m{mesh::Vec3::Zero()};  // closest point on the bone, unit m
  double penetration_m{0.0};  // how deep the newest tip is behind the plane (>= 0), unit m
  double shaft_offset_m{0.0};  // 0: the tip sphere; > 0: a shaft point this far up the axis
  int triangle{-1};            // RigidObstacle triangle index of the surface point
};

struct ObstaclePlanes {
  std::array<ObstaclePlane, kMaxObstaclePlanes> planes{};
  int count{0};
  double max_penetration_m() const {
    double p = 0.0;
    for (int i = 0; i < count; ++i) p = std::max(p, planes[static_cast<std::size_t>(i)].penetration_m);
    return p;
  }
};

// One query: where the free side is, the newest pose, the tool.
struct ObstacleQuery {
  mesh::Vec3 free_tip_m{mesh::Vec3::Zero()};  // a tip position known to be free (the proxy)
  bool free_known{false};  // false: normals are the surface's outward normals
  mesh::Vec3 tip_m{mesh::Vec3::Zero()};       // newest tip: penetration measured here
  mesh::Vec3 axis{mesh::Vec3::UnitZ()};       // shaft direction (unit, tip towards handle)
  ToolShape shape;
  double reach_m{0.003};  // surface points within this distance of the tool's surface, unit m
};

struct RigidObstacleOptions {
  double merge_cos{0.985};          // planes whose normals are closer than ~10 degrees merge
  double shaft_box_length_m{0.01};  // the shaft is searched in boxes of this length, unit m
};

class RigidObstacle {
 public:
  // nullptr when the scene has no rigid surface: nothing built, nothing paid per step.
  static std::unique_ptr<const RigidObstacle> build(const std::vector<scene::RigidSurface>& surfaces,
                                                    const RigidObstacleOptions& options = {});
  RigidObstacle(const std::vector<scene::RigidSurface>& surfaces,
                const RigidObstacleOptions& options);
  ~RigidObstacle();

  // Per caller (e.g. per station): candidate lists, sized at make_scratch, reused.
  struct Candidate {
    double gap_m;  // distance of the part's surface from the bone at the free pose, unit m
    mesh::Vec3 surface_point_m;
    mesh::Vec3 normal;
    double radius_m;
    double shaft_offset_m;
    int triangle;
  };
  struct Scratch {
    std::vector<int> triangles;
    std::vector<std::uint32_t> stamp;  // per triangle: last pass that saw it
    std::uint32_t pass{0};
    std::vector<Candidate> candidates;
  };
  Scratch make_scratch() const;

  // The constraint planes of the tool near q.free_tip_m (nearest first, merged when nearly
  // parallel), penetration measured at q.tip_m.
  void query(const ObstacleQuery& q, Scratch& scratch, ObstaclePlanes& out) const;

  // Closest surface point over every triangle (BVH).
  struct Closest {
    int triangle{-1};
    mesh::Vec3 point_m{mesh::Vec3::Zero()};
    double distance_m{0.0};
  };
  Closest closest(const mesh::Vec3& p) const;
  // Generalized winding number of the closed surfaces at p (brute force, O(triangles)): 1 inside
  // the solid bone, 0 outside. For start-up and tests, not per step.
  double winding_number(const mesh::Vec3& p) const;
  bool inside(const mesh::Vec3& p) const { return winding_number(p) > 0.5; }

  int num_triangles() const { return static_cast<int>(triangles_.size()); }
  const std::vector<mesh::Vec3>& vertices_m() const { return vertices_m_; }
  const std::vector<mesh::Tri>& triangles() const { return triangles_; }
  const mesh::Vec3& face_normal(int t) const { return face_normals_[static_cast<std::size_t>(t)]; }

 private:
  void collect(const mesh::Vec3& lo, const mesh::Vec3& hi, Scratch& s) const;
  RigidObstacleOptions options_;
  std::vector<mesh::Vec3> vertices_m_;  // all surfaces, concatenated
  std::vector<mesh::Tri> triangles_;
  std::vector<mesh::Vec3> face_normals_;  // outward, unit
  // Per triangle a bounding sphere (centroid, radius), to skip far triangles before the exact
  // closest-point computation.
  std::vector<mesh::Vec3> centroids_m_;
  mesh::Vec3 lo_m_{mesh::Vec3::Zero()}, hi_m_{mesh::Vec3::Zero()};  // bounding box of all vertices
  std::vector<double> bound_radii_m_;
  std::unique_ptr<fusion::TriangleBvh> bvh_;
};

}  // namespace neurosim::interaction
