// Rigid obstacles of a compiled scene (the skull): constant closed triangle surfaces with their
// openings, for tool contact. Never deformed and never part of the FEM solve. Plain C++ (part of
// scene::Model, no protobuf).
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <cmath>

#include <string>
#include <vector>

namespace neurosim::scene {

// A craniotomy: the solid cylinder of radius_m around the axis through center_m along `axis`
// (unit, pointing out of the head), within half_length_m of center_m along it. Unit m.
struct RigidOpening {
  mesh::Vec3 center_m{mesh::Vec3::Zero()};
  mesh::Vec3 axis{mesh::Vec3::UnitZ()};  // unit length
  double radius_m{0.0};
  double half_length_m{0.0};
  std::string provenance;

  // Distance of p from the axis and its signed position along it, unit m.
  double radial_m(const mesh::Vec3& p) const {
    const mesh::Vec3 d = p - center_m;
    return (d - d.dot(axis) * axis).norm();
  }
  double axial_m(const mesh::Vec3& p) const { return (p - center_m).dot(axis); }
  // Inside the cut cylinder, shrunk by margin_m radially (margin 0: the cylinder itself).
  bool contains(const mesh::Vec3& p, double margin_m = 0.0) const {
    return std::abs(axial_m(p)) <= half_length_m && radial_m(p) < radius_m - margin_m;
  }
};

// A closed, outward-oriented triangle surface (checked at load: every edge shared by exactly two
// triangles in opposite directions, positive enclosed volume).
struct RigidSurface {
  std::string id;
  std::vector<mesh::Vec3> vertices_m;  // unit m
  std::vector<mesh::Tri> triangles;    // outward (right-hand normal points out of the solid)
  std::vector<RigidOpening> openings;
  std::string provenance;
  std::string file;  // where it was read from
  double enclosed_volume_m3{0.0};
};

}  // namespace neurosim::scene
