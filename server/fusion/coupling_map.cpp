#include "server/fusion/coupling_map.hpp"

#include "server/fusion/cgal_aabb.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::fusion {
namespace {

using namespace cgal_aabb;

// For each node, the closest point on the triangle set (tree finds the triangle, Ericson's
// routine gives the weights).
std::vector<SurfacePoint> closest_points(const std::vector<Vec3>& node_pos,
                                         const std::vector<int>& nodes,
                                         const std::vector<Vec3>& tri_pos,
                                         const std::vector<Tri>& tris, DistanceSummary& summary) {
  std::vector<T3> kt;
  kt.reserve(tris.size());
  for (const Tri& t : tris)
    kt.emplace_back(to_point(tri_pos[t[0]]), to_point(tri_pos[t[1]]), to_point(tri_pos[t[2]]));
  Tree tree(kt.cbegin(), kt.cend());
  tree.accelerate_distance_queries();
  std::vector<SurfacePoint> out;
  out.reserve(nodes.size());
  summary = {};
  double sum = 0.0;
  for (std::size_t i = 0; i < nodes.size(); ++i) {
    const Vec3& p = node_pos[nodes[i]];
    const auto hit = tree.closest_point_and_primitive(to_point(p));
    const int ti = static_cast<int>(hit.second - kt.cbegin());
    const Tri& t = tris[ti];
    SurfacePoint sp = closest_point_on_triangle(p, tri_pos[t[0]], tri_pos[t[1]], tri_pos[t[2]]);
    sp.triangle = ti;
    if (!std::isfinite(sp.distance_m)) {
      throw std::runtime_error("coupling map: non-finite distance at node " +
                               std::to_string(nodes[i]));
    }
    sum += sp.distance_m;
    if (sp.distance_m > summary.max_m || summary.argmax < 0) {
      summary.max_m = sp.distance_m;
      summary.argmax = static_cast<int>(i);
    }
    out.push_back(sp);
  }
  summary.mean_m = nodes.empty() ? 0.0 : sum / static_cast<double>(nodes.size());
  return out;
}

void check_indices(const std::vector<Tri>& tris, std::size_t n, const std::string& what) {
  for (std::size_t i = 0; i < tris.size(); ++i) {
    for (int v : tris[i]) {
      if (v < 0 || static_cast<std::size_t>(v) >= n) {
        throw std::invalid_argument("coupling map: " + what + " triangle " + std::to_string(i) +
                                    " has vertex " + std::to_string(v) + " out of range [0, " +
                                    std::to_string(n) + ")");
      }
    }
  }
}

}  // namespace

SurfacePoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  SurfacePoint r;
  auto set = [&](double u, double v, double w) {
    r.weights = {u, v, w};
    r.point_m = u * a + v * b + w * c;
    r.distance_m = (p - r.point_m).norm();
    return r;
  };
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return set(1, 0, 0);
  const Vec3 bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return set(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return set(1 - v, v, 0);
  }
  const Vec3 cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return set(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return set(1 - w, 0, w);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return set(0, 1 - w, w);
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return set(1 - v - w, v, w);
}

CouplingMap build_coupling_map(const std::vector<Vec3>& host_vertices_m,
                               const NewBoundary& boundary, const TriangleSurface& embedded) {
  if (boundary.triangles.empty()) {
    throw std::invalid_argument(
        "coupling map: the new boundary S' is empty (B does not overlap A)");
  }
  if (embedded.triangles.empty()) {
    throw std::invalid_argument("coupling map: surface '" + embedded.name + "' has no triangles");
  }
  check_indices(boundary.triangles, host_vertices_m.size(), "new boundary");
  check_indices(embedded.triangles, embedded.vertices_m.size(), "surface '" + embedded.name + "'");
  CouplingMap map;
  for (const Tri& t : embedded.triangles)
    map.embedded_nodes.insert(map.embedded_nodes.end(), t.begin(), t.end());
  std::sort(map.embedded_nodes.begin(), map.embedded_nodes.end());
  map.embedded_nodes.erase(std::unique(map.embedded_nodes.begin(), map.embedded_nodes.end()),
                           map.embedded_nodes.end());
  map.boundary_nodes = boundary.vertices();
  for (int v : map.boundary_nodes) {
    if (!host_vertices_m[v].allFinite()) {
      throw std::invalid_argument("coupling map: host vertex " + std::to_string(v) +
                                  " is not finite");
    }
  }
  for (int v : map.embedded_nodes) {
    if (!embedded.vertices_m[v].allFinite()) {
      throw std::invalid_argument("coupling map: vertex " + std::to_string(v) + " of '" +
                                  embedded.name + "' is not finite");
    }
  }
  map.embedded_on_boundary =
      closest_points(embedded.vertices_m, map.embedded_nodes, host_vertices_m, boundary.triangles,
                     map.embedded_to_boundary);
  map.boundary_on_embedded =
      closest_points(host_vertices_m, map.boundary_nodes, embedded.vertices_m, embedded.triangles,
                     map.boundary_to_embedded);
  return map;
}

}  // namespace neurosim::fusion
