#include "server/interaction/contact_surface.hpp"

#include <algorithm>
#include <stdexcept>
#include <utility>

namespace neurosim::interaction {

TrianglePoint closest_on_triangle(const mesh::Vec3& x, const std::array<mesh::Vec3, 3>& p) {
  // Voronoi regions of the vertices, then of the edges, else the face.
  TrianglePoint r;
  const mesh::Vec3 ab = p[1] - p[0], ac = p[2] - p[0], ap = x - p[0];
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  auto vertex = [&](int a) {
    r.point_m = p[a];
    r.weights = {0.0, 0.0, 0.0};
    r.weights[a] = 1.0;
    r.feature = TriangleFeature::kVertex;
    r.a = a;
    return r;
  };
  auto edge = [&](int a, double t) {  // from local vertex a to a + 1, parameter t
    const int b = (a + 1) % 3;
    r.point_m = p[a] + t * (p[b] - p[a]);
    r.weights = {0.0, 0.0, 0.0};
    r.weights[a] = 1.0 - t;
    r.weights[b] = t;
    r.feature = TriangleFeature::kEdge;
    r.a = a;
    return r;
  };
  if (d1 <= 0.0 && d2 <= 0.0) return vertex(0);
  const mesh::Vec3 bp = x - p[1];
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return vertex(1);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return edge(0, d1 / (d1 - d3));
  const mesh::Vec3 cp = x - p[2];
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return vertex(2);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return edge(2, 1.0 - d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return edge(1, (d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(denom > 0.0)) return vertex(0);  // degenerate triangle
  const double v = vb / denom, w = vc / denom;
  r.weights = {1.0 - v - w, v, w};
  r.point_m = p[0] + v * ab + w * ac;
  r.feature = TriangleFeature::kFace;
  r.a = 0;
  return r;
}

ContactSurface::ContactSurface(const ContactSurfaceDefinition& def) {
  if (def.host == nullptr || def.contact_slot == nullptr || def.fixed_nodes == nullptr)
    throw std::invalid_argument("ContactSurface: incomplete definition");
  const mesh::TetMesh& host = *def.host;
  const auto& slot = *def.contact_slot;
  const auto& fixed = *def.fixed_nodes;
  auto is_fixed = [&](int v) { return std::binary_search(fixed.begin(), fixed.end(), v); };
  // The host's outer triangles (S' and carved faces have no contact slot: not contactable).
  for (const auto& tri : host.surface()) {
    SurfaceTriangle t;
    int mobile = 0;
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      t.node[k] = tri[k];
      t.slot[k] = slot[tri[k]];
      if (t.slot[k] >= 0) {
        ++mobile;
      } else if (!is_fixed(tri[k])) {
        ok = false;
      }
    }
    if (ok && mobile > 0) triangles_.push_back(t);
  }
  // Edge incidence: how many contactable triangles share each edge.
  std::vector<std::pair<std::pair<int, int>, int>> edges;  // (sorted nodes), triangle*3 + k
  edges.reserve(3 * triangles_.size());
  for (std::size_t t = 0; t < triangles_.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = triangles_[t].node[k], b = triangles_[t].node[(k + 1) % 3];
      edges.push_back({{std::min(a, b), std::max(a, b)}, static_cast<int>(3 * t) + k});
    }
  std::sort(edges.begin(), edges.end());
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j].first == edges[i].first) ++j;
    for (std::size_t k = i; k < j; ++k)
      triangles_[edges[k].second / 3].edge_triangles[edges[k].second % 3] = static_cast<int>(j - i);
    i = j;
  }
  // Grid over the rest centroids; queries are widened by the largest triangle radius.
  double edge_sum = 0.0;
  centroid_.reserve(triangles_.size());
  radius_m_.reserve(triangles_.size());
  for (const auto& t : triangles_) {
    const auto& v = host.vertices();
    const mesh::Vec3 c = (v[t.node[0]] + v[t.node[1]] + v[t.node[2]]) / 3.0;
    centroid_.push_back(c);
    double radius = 0.0;
    for (int k = 0; k < 3; ++k) {
      radius = std::max(radius, (v[t.node[k]] - c).norm());
      edge_sum += (v[t.node[k]] - v[t.node[(k + 1) % 3]]).norm();
    }
    radius_m_.push_back(radius);
    max_radius_m_ = std::max(max_radius_m_, radius);
  }
  if (triangles_.empty()) return;
  mean_edge_m_ = edge_sum / (3.0 * static_cast<double>(triangles_.size()));
  grid_ = PointGrid(centroid_, 2.0 * mean_edge_m_);
}

void ContactSurface::query(const mesh::Vec3& lo, const mesh::Vec3& hi,
                           std::vector<int>& out) const {
  const mesh::Vec3 pad = mesh::Vec3::Constant(max_radius_m_);
  grid_.query(lo - pad, hi + pad, out);
}

}  // namespace neurosim::interaction
