#include "server/interaction/surface_probe.hpp"

#include "server/interaction/contact_surface.hpp"
#include "server/interaction/rigid_obstacle.hpp"

#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {
namespace {

void check_surface(const mesh::TetMesh& mesh, const char* what) {
  if (mesh.surface().empty())
    throw std::invalid_argument(std::string(what) + ": the mesh has no surface triangles");
}

}  // namespace

std::optional<SurfacePoint> top_of_surface(const mesh::TetMesh& mesh, double x_m, double y_m) {
  if (!std::isfinite(x_m) || !std::isfinite(y_m))
    throw std::invalid_argument("top_of_surface: non-finite (x, y)");
  check_surface(mesh, "top_of_surface");
  const auto& v = mesh.vertices();
  double best = -std::numeric_limits<double>::infinity();
  SurfacePoint out;
  for (const auto& t : mesh.surface()) {
    const mesh::Vec3 &a = v[t[0]], &b = v[t[1]], &c = v[t[2]];
    const mesh::Vec3 n = (b - a).cross(c - a);
    if (n.z() <= 0.0) continue;  // faces looking up only (this also excludes vertical ones)
    // Barycentric coordinates of (x, y) in the triangle's projection on z = 0.
    const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
    const double l1 = ((x_m - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y_m - a.y())) / det;
    const double l2 = ((b.x() - a.x()) * (y_m - a.y()) - (x_m - a.x()) * (b.y() - a.y())) / det;
    if (l1 < 0.0 || l2 < 0.0 || l1 + l2 > 1.0) continue;
    const mesh::Vec3 p = a + l1 * (b - a) + l2 * (c - a);
    if (p.z() > best) {
      best = p.z();
      out.point_m = p;
      out.normal = n.normalized();
    }
  }
  if (!std::isfinite(best)) return std::nullopt;
  return out;
}

SurfacePoint closest_on_surface(const mesh::TetMesh& mesh, const mesh::Vec3& x_m) {
  if (!x_m.allFinite()) throw std::invalid_argument("closest_on_surface: non-finite point");
  check_surface(mesh, "closest_on_surface");
  const auto& v = mesh.vertices();
  double best = std::numeric_limits<double>::infinity();
  SurfacePoint out;
  for (const auto& t : mesh.surface()) {
    const std::array<mesh::Vec3, 3> p{v[t[0]], v[t[1]], v[t[2]]};
    const TrianglePoint at = closest_on_triangle(x_m, p);
    const double d = (x_m - at.point_m).squaredNorm();
    if (d < best) {
      best = d;
      out.point_m = at.point_m;
      out.normal = (p[1] - p[0]).cross(p[2] - p[0]).normalized();
    }
  }
  return out;
}

std::optional<mesh::Vec3> at_distance_along(const mesh::TetMesh& mesh, const mesh::Vec3& at,
                                            const mesh::Vec3& axis, double distance_m, double max_m) {
  if (!at.allFinite() || !axis.allFinite() || !std::isfinite(distance_m) || !std::isfinite(max_m))
    throw std::invalid_argument("at_distance_along: non-finite input");
  if (distance_m < 0.0) throw std::invalid_argument("at_distance_along: negative distance");
  if (std::abs(axis.norm() - 1.0) > 1e-9) throw std::invalid_argument("at_distance_along: axis not unit");
  check_surface(mesh, "at_distance_along");
  constexpr double kTolerance = 1e-10, kStep = 1e-4;  // unit m
  auto g = [&](double t) {
    const mesh::Vec3 x = at + t * axis;
    const SurfacePoint near = closest_on_surface(mesh, x);
    const double gap = (x - near.point_m).norm();
    return (near.normal.dot(x - near.point_m) < 0.0 ? -gap : gap) - distance_m;
  };
  double lo = 0.0, g_lo = -distance_m, hi = distance_m, g_hi = g(hi);
  while (g_hi < -kTolerance) {
    lo = hi;
    g_lo = g_hi;
    hi += kStep;
    if (hi > max_m) return std::nullopt;
    g_hi = g(hi);
  }
  double t = hi, gt = g_hi;
  int side = 0;
  for (int it = 0; it < 200 && std::abs(gt) > kTolerance && hi - lo > 1e-13; ++it) {
    t = (lo * g_hi - hi * g_lo) / (g_hi - g_lo);
    gt = g(t);
    if (gt < 0.0) {
      lo = t;
      g_lo = gt;
      if (side == -1) g_hi *= 0.5;
      side = -1;
    } else {
      hi = t;
      g_hi = gt;
      if (side == 1) g_lo *= 0.5;
      side = 1;
    }
  }
  if (!(std::abs(gt) <= 1e-9)) return std::nullopt;
  return at + t * axis;
}

mesh::Vec3 top_of_obstacle(const RigidObstacle& obstacle, double step_m) {
  if (!std::isfinite(step_m) || step_m <= 0.0)
    throw std::invalid_argument("top_of_obstacle: step " + std::to_string(step_m) +
                                " m is not finite and > 0");
  mesh::Vec3 lo = obstacle.vertices_m().front(), hi = lo;
  for (const auto& v : obstacle.vertices_m()) {
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
  }
  const mesh::Vec3 down(0, 0, -1);
  mesh::Vec3 top(0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()), hi.z() + 0.01);
  while (!obstacle.inside(top)) {
    top += step_m * down;
    if (top.z() < lo.z())
      throw std::invalid_argument(
          "top_of_obstacle: the vertical line through the bounding box's centre misses the "
          "obstacle");
  }
  return top;
}

}  // namespace neurosim::interaction
