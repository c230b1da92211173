#include "server/fusion/exposure.hpp"

#include "server/fusion/inclusion.hpp"
#include "server/fusion/triangle_bvh.hpp"
#include "server/fusion/triangle_surface.hpp"

#include <cmath>
#include <stdexcept>
#include <vector>

namespace neurosim::fusion {

Exposure embedded_outside_host(const mesh::TetMesh& host, const mesh::TetMesh& embedded,
                               const ExposureOptions& options) {
  if (!(options.tolerance_m >= 0.0) || !std::isfinite(options.tolerance_m))
    throw std::invalid_argument("embedded_outside_host: tolerance_m must be finite and >= 0");
  const TriangleSurface a = TriangleSurface::of(host, "host");
  const TriangleBvh bvh(a.vertices_m, a.triangles);
  Exposure out;
  const auto& nodes = embedded.surface_vertices();
  out.surface_nodes = static_cast<int>(nodes.size());
  out.outside.assign(embedded.num_vertices(), 0);
  // Nodes within the tolerance of A's surface are inside by definition (and the parity test is
  // undefined on it); the others are classified exactly.
  std::vector<int> far_nodes;
  std::vector<double> far_distance_m;
  std::vector<Vec3> far_points_m;
  for (int v : nodes) {
    const Vec3& p = embedded.vertices()[v];
    const double d = bvh.closest(p).distance_m;
    if (d <= options.tolerance_m) continue;
    far_nodes.push_back(v);
    far_distance_m.push_back(d);
    far_points_m.push_back(p);
  }
  const std::vector<char> outside = outside_closed_surface(far_points_m, a);
  for (std::size_t k = 0; k < far_nodes.size(); ++k) {
    if (!outside[k]) continue;
    out.outside[far_nodes[k]] = 1;
    ++out.nodes_outside;
    if (far_distance_m[k] > out.max_distance_m) {
      out.max_distance_m = far_distance_m[k];
      out.farthest_node = far_nodes[k];
    }
  }
  return out;
}

}  // namespace neurosim::fusion
