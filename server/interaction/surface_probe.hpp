// Points on a mesh's boundary surface for placing a tool (benches, tests, tools): the highest
// surface point on a vertical line, the closest surface point to a point, and the top of a rigid
// obstacle. Brute force over the surface triangles (O(triangles) per call): for set-up and
// measurement, not for the step.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <optional>

namespace neurosim::interaction {

class RigidObstacle;  // rigid_obstacle.hpp

// A point of the boundary surface (unit m) and the outward unit normal of its triangle.
struct SurfacePoint {
  mesh::Vec3 point_m{mesh::Vec3::Zero()};
  mesh::Vec3 normal{mesh::Vec3::UnitZ()};
};

// The highest point of the surface on the vertical line through (x_m, y_m) (a ray from +z), among
// triangles facing up; none if the line misses them. Throws std::invalid_argument on a
// non-finite coordinate or a mesh without surface triangles.
std::optional<SurfacePoint> top_of_surface(const mesh::TetMesh& mesh, double x_m, double y_m);

// The closest point of the surface triangles to x_m (Euclidean). Throws std::invalid_argument on
// a non-finite point or a mesh without surface triangles.
SurfacePoint closest_on_surface(const mesh::TetMesh& mesh, const mesh::Vec3& x_m);

// The first point x = at + t axis (t >= 0) whose signed distance to the surface triangles is
// distance_m (>= 0): the distance to closest_on_surface's point, negative where x lies behind
// that triangle's plane. `at` is a point of the surface, so the distance at t is at most t: the
// search starts at t = distance_m, steps out by 0.1 mm to the first crossing, then refines it by
// false position (Illinois) to 1e-10 m (a distance within 1e-10 m at t = distance_m is taken as
// it is: with distance_m = 0 the answer is `at` itself, not the line's exit from the body). The
// tool placement of the contact slide at a fixed gap depth (tests, bench). None if no such point
// lies within max_m along the axis. Throws std::invalid_argument on a non-finite input, a
// negative distance, an axis that is not unit, or a mesh without surface triangles.
std::optional<mesh::Vec3> at_distance_along(const mesh::TetMesh& mesh, const mesh::Vec3& at,
                                            const mesh::Vec3& axis, double distance_m,
                                            double max_m = 0.03);

// Where the vertical line through the centre of the obstacle's bounding box enters it from above
// (the top of the skull): from 10 mm above the box down in steps of step_m (unit m) to the first
// point inside (generalized winding number), so within step_m below the surface. Throws
// std::invalid_argument for a step that is not finite and > 0, or when the line leaves the box
// without entering the obstacle.
mesh::Vec3 top_of_obstacle(const RigidObstacle& obstacle, double step_m = 5e-5);

}  // namespace neurosim::interaction
