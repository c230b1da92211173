#include "server/interaction/contact_surface.hpp"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace neurosim::interaction {

bool project_along_normals(const mesh::Vec3& x, const std::array<mesh::Vec3, 3>& p,
                           const std::array<mesh::Vec3, 3>& nn, TrianglePoint& at,
                           mesh::Vec3& unit_normal, double& height_m) {
  const mesh::Vec3 e1 = p[1] - p[0], e2 = p[2] - p[0];
  const mesh::Vec3 n1 = nn[1] - nn[0], n2 = nn[2] - nn[0];
  const mesh::Vec3 flat = e1.cross(e2);
  const double area2 = flat.squaredNorm();
  if (!(area2 > 0.0)) return false;
  // Start: the flat projection's barycentric coordinates and height.
  const mesh::Vec3 r0 = x - p[0];
  double u = r0.cross(e2).dot(flat) / area2;
  double v = e1.cross(r0).dot(flat) / area2;
  double h = r0.dot(flat) / std::sqrt(area2);
  const double scale = std::sqrt(std::max(e1.squaredNorm(), e2.squaredNorm()));
  bool converged = false;
  for (int it = 0; it < 12; ++it) {
    const mesh::Vec3 nv = nn[0] + u * n1 + v * n2;
    const mesh::Vec3 res = p[0] + u * e1 + v * e2 + h * nv - x;
    if (res.norm() <= 1e-13 * scale) {
      converged = true;
      break;
    }
    Eigen::Matrix3d j;
    j.col(0) = e1 + h * n1;
    j.col(1) = e2 + h * n2;
    j.col(2) = nv;
    const double det = j.determinant();
    if (!(std::abs(det) > 1e-300)) return false;
    const mesh::Vec3 step = j.inverse() * res;
    u -= step[0];
    v -= step[1];
    h -= step[2];
    if (!std::isfinite(u + v + h) || std::abs(u) > 4.0 || std::abs(v) > 4.0) return false;
  }
  if (!converged) {
    const mesh::Vec3 nv = nn[0] + u * n1 + v * n2;
    if ((p[0] + u * e1 + v * e2 + h * nv - x).norm() > 1e-9 * scale) return false;
  }
  constexpr double kTol = 1e-12;
  if (u < -kTol || v < -kTol || u + v > 1.0 + kTol) return false;
  const mesh::Vec3 nv = nn[0] + u * n1 + v * n2;
  const double len = nv.norm();
  if (!(len > 0.0)) return false;
  unit_normal = nv / len;
  at.point_m = p[0] + u * e1 + v * e2;
  at.weights = {1.0 - u - v, u, v};
  height_m = h * len;
  at.feature = TriangleFeature::kFace;
  at.a = 0;
  return true;
}

ContactSurface::ContactSurface(const ContactSurfaceDefinition& def) {
  if (def.host == nullptr || def.contact_slot == nullptr || def.fixed_nodes == nullptr)
    throw std::invalid_argument("ContactSurface: incomplete definition");
  const mesh::TetMesh& host = *def.host;
  const auto& slot = *def.contact_slot;
  const auto& fixed = *def.fixed_nodes;
  auto is_fixed = [&](int v) { return std::binary_search(fixed.begin(), fixed.end(), v); };
  // The host's outer triangles, less the covered ones (S' on a carved host); a triangle with a
  // node that has no slot and is not fixed is not contactable either.
  auto covered = [&](const mesh::Tri& tri) {
    if (def.covered_faces == nullptr) return false;
    std::array<int, 3> f{tri[0], tri[1], tri[2]};
    std::sort(f.begin(), f.end());
    return std::binary_search(def.covered_faces->begin(), def.covered_faces->end(), f);
  };
  for (const auto& tri : host.surface()) {
    if (covered(tri)) continue;
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
  // Rest geometry for spread loads: vertices, normals, each node's mean incident edge.
  const auto& v = host.vertices();
  std::vector<double> edge_of(v.size(), 0.0);
  std::vector<int> edges_of(v.size(), 0);
  rest_m_.reserve(triangles_.size());
  normal_.reserve(triangles_.size());
  spread_area_m2_.reserve(triangles_.size());
  spread_longest_m_.reserve(triangles_.size());
  for (const auto& t : triangles_) {
    rest_m_.push_back({v[t.node[0]], v[t.node[1]], v[t.node[2]]});
    {
      // The spread's per-triangle constants (its area and longest edge, as spread() used to
      // form them per call: the same expressions, the same values).
      const auto& x = rest_m_.back();
      const mesh::Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0];
      spread_area_m2_.push_back(0.5 * e1.cross(e2).norm());
      spread_longest_m_.push_back(std::max({e1.norm(), e2.norm(), (x[2] - x[1]).norm()}));
    }
    const mesh::Vec3 nt = (v[t.node[1]] - v[t.node[0]]).cross(v[t.node[2]] - v[t.node[0]]);
    normal_.push_back(nt.norm() > 0.0 ? mesh::Vec3(nt.normalized()) : mesh::Vec3::Zero());
    for (int k = 0; k < 3; ++k) {
      const double len = (v[t.node[k]] - v[t.node[(k + 1) % 3]]).norm();
      for (int e : {t.node[k], t.node[(k + 1) % 3]}) {
        edge_of[e] += len;
        ++edges_of[e];
      }
    }
  }
  node_edge_m_.reserve(triangles_.size());
  for (const auto& t : triangles_) {
    std::array<double, 3> h{};
    for (int k = 0; k < 3; ++k) h[k] = edge_of[t.node[k]] / edges_of[t.node[k]];
    node_edge_m_.push_back(h);
  }
  std::vector<mesh::Vec3> normal_of(v.size(), mesh::Vec3::Zero());
  for (const auto& t : triangles_) {
    const mesh::Vec3 area2 = (v[t.node[1]] - v[t.node[0]]).cross(v[t.node[2]] - v[t.node[0]]);
    for (int k = 0; k < 3; ++k) normal_of[t.node[k]] += area2;
  }
  node_normal_.reserve(triangles_.size());
  for (std::size_t i = 0; i < triangles_.size(); ++i) {
    std::array<mesh::Vec3, 3> nn;
    for (int k = 0; k < 3; ++k) {
      const mesh::Vec3& sum = normal_of[triangles_[i].node[k]];
      nn[k] = sum.norm() > 0.0 ? mesh::Vec3(sum.normalized()) : normal_[i];
    }
    node_normal_.push_back(nn);
  }
  grid_ = PointGrid(centroid_, 2.0 * mean_edge_m_);
  ranked_sphere_.resize(triangles_.size());
  for (std::size_t t = 0; t < triangles_.size(); ++t) {
    const mesh::Vec3& c = centroid_[t];
    ranked_sphere_[grid_.rank(static_cast<int>(t))] = {c.x(), c.y(), c.z(), radius_m_[t]};
  }
}

void ContactSurface::query_tool(const mesh::Vec3& lo, const mesh::Vec3& hi, bool has_near,
                                const mesh::Vec3& near_lo, const mesh::Vec3& near_hi,
                                const mesh::Vec3& a, const mesh::Vec3& b, double near_m,
                                double sphere_m, std::vector<int>& ranks) const {
  if (!(sphere_m >= 0.0))
    throw std::invalid_argument("ContactSurface::query_tool: sphere reach must be >= 0");
  const mesh::Vec3 pad = mesh::Vec3::Constant(max_radius_m_);
  const std::size_t first = ranks.size();
  grid_.query_ranks(lo - pad, hi + pad, has_near, near_lo - pad, near_hi + pad, a, b,
                    (near_m + max_radius_m_) * (1.0 + 1e-6), ranks);
  std::size_t kept = first;
  for (std::size_t i = first; i < ranks.size(); ++i) {
    const auto& s = ranked_sphere_[ranks[i]];
    const mesh::Vec3 c(s[0], s[1], s[2]);
    const double bound = (s[3] + sphere_m) * (1.0 + 1e-6);
    if ((c - closest_on_segment(c, a, b)).squaredNorm() <= bound * bound) ranks[kept++] = ranks[i];
  }
  ranks.resize(kept);
}

void ContactSurface::query(const mesh::Vec3& lo, const mesh::Vec3& hi,
                           std::vector<int>& out) const {
  const mesh::Vec3 pad = mesh::Vec3::Constant(max_radius_m_);
  grid_.query(lo - pad, hi + pad, out);
}

void ContactSurface::query_near(const mesh::Vec3& lo, const mesh::Vec3& hi, const mesh::Vec3& a,
                                const mesh::Vec3& b, double reach_m, std::vector<int>& out) const {
  const mesh::Vec3 pad = mesh::Vec3::Constant(max_radius_m_);
  grid_.query_near(lo - pad, hi + pad, a, b, (reach_m + max_radius_m_) * (1.0 + 1e-6), out);
}

PointGrid::CellRange ContactSurface::query_cells(const mesh::Vec3& lo,
                                                const mesh::Vec3& hi) const {
  const mesh::Vec3 pad = mesh::Vec3::Constant(max_radius_m_);
  return grid_.cells(lo - pad, hi + pad);
}

double ContactSurface::edge_at_m(int t, const std::array<double, 3>& bary) const {
  const auto& h = node_edge_m_[t];
  return bary[0] * h[0] + bary[1] * h[1] + bary[2] * h[2];
}

bool ContactSurface::spread(const mesh::Vec3& p, const mesh::Vec3& n, double rho_m,
                            std::vector<int>& scratch, SpreadLoad& out,
                            std::array<mesh::Vec3, kSpreadNodes>* gradient) const {
  if (!(rho_m > 0.0)) return false;
  scratch.clear();
  const mesh::Vec3 r = mesh::Vec3::Constant(rho_m);
  query(p - r, p + r, scratch);
  // Accumulated weights per node (a linear list: a spread covers a few dozen nodes at most).
  constexpr int kMost = 4 * kSpreadNodes;
  std::array<int, kMost> node{};
  std::array<int, kMost> slot{};
  std::array<double, kMost> weight{};
  std::array<mesh::Vec3, kMost> slope;  // with `gradient`: d weight / d p before normalizing
  int count = 0, lost = 0;
  double total = 0.0;
  const double inv_rho2 = 1.0 / (rho_m * rho_m);
  for (int t : scratch) {
    // |c - p| > radius + rho, the square root taken only within 1e-9 of the bound (the same
    // decision as the norm's).
    const double d2 = (centroid_[t] - p).squaredNorm();
    {
      const double bound = radius_m_[t] + rho_m;
      const double lo = bound * (1.0 - 1e-9), hi = bound * (1.0 + 1e-9);
      if (d2 > hi * hi || (d2 > lo * lo && std::sqrt(d2) > bound)) continue;
    }
    if (!(normal_[t].dot(n) > 0.0)) continue;
    const double longest = spread_longest_m_[t];
    const int sub = std::clamp(static_cast<int>(std::ceil(3.0 * longest / rho_m)), 1, 8);
    // Every sample below has barycentric coordinates >= 1 / (3 sub), so it lies within
    // (1 - 1/sub) radius of the centroid: a triangle whose centroid is farther than that plus rho
    // (with 1e-6 to spare for round-off) has no sample within rho and adds nothing. Skipping it
    // leaves every sum as it was (at the vertices' spreads this is most of the triangles that
    // pass the test above with no sample within rho; those were 47 % of the triangles sampled).
    {
      const double inner = ((1.0 - 1.0 / sub) * radius_m_[t] + rho_m) * (1.0 + 1e-6);
      if (d2 > inner * inner) continue;
    }
    const auto& x = rest_m_[t];
    const mesh::Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0];
    const double area = spread_area_m2_[t];
    const double da = area / (sub * sub);
    std::array<double, 3> acc{0.0, 0.0, 0.0};
    std::array<mesh::Vec3, 3> acc_slope{mesh::Vec3::Zero(), mesh::Vec3::Zero(),
                                        mesh::Vec3::Zero()};
    auto sample = [&](double u, double w) {
      const mesh::Vec3 y = x[0] + u * e1 + w * e2;
      const double s2 = (y - p).squaredNorm() * inv_rho2;
      if (s2 >= 1.0) return;
      const double k = (1.0 - s2) * (1.0 - s2) * da;
      acc[0] += k * (1.0 - u - w);
      acc[1] += k * u;
      acc[2] += k * w;
      if (gradient != nullptr) {
        // d k / d p = 4 (1 - s^2) (y - p) / rho^2 da
        const mesh::Vec3 dk = (4.0 * (1.0 - s2) * inv_rho2 * da) * (y - p);
        acc_slope[0] += (1.0 - u - w) * dk;
        acc_slope[1] += u * dk;
        acc_slope[2] += w * dk;
      }
    };
    const double inv = 1.0 / sub;
    for (int i = 0; i < sub; ++i)
      for (int j = 0; i + j < sub; ++j) {
        sample((i + 1.0 / 3.0) * inv, (j + 1.0 / 3.0) * inv);                          // upward
        if (i + j + 2 <= sub) sample((i + 2.0 / 3.0) * inv, (j + 2.0 / 3.0) * inv);  // downward
      }
    for (int k = 0; k < 3; ++k) {
      if (!(acc[k] > 0.0)) continue;
      total += acc[k];
      const int id = triangles_[t].node[k];
      int at = 0;
      while (at < count && node[at] != id) ++at;
      if (at == count) {
        if (count == kMost) {
          ++lost;
          continue;
        }
        node[count] = id;
        slot[count] = triangles_[t].slot[k];
        weight[count] = 0.0;
        slope[count].setZero();
        ++count;
      }
      weight[at] += acc[k];
      if (gradient != nullptr) slope[at] += acc_slope[k];
    }
  }
  if (count == 0 || !(total > 0.0)) return false;
  // The largest kSpreadNodes weights, in descending order (ties by node id: deterministic).
  std::array<int, kMost> order{};
  for (int k = 0; k < count; ++k) order[k] = k;
  std::sort(order.begin(), order.begin() + count, [&](int a, int b) {
    return weight[a] != weight[b] ? weight[a] > weight[b] : node[a] < node[b];
  });
  out.nodes = std::min(count, kSpreadNodes);
  out.dropped = count - out.nodes + lost;
  double kept = 0.0;
  for (int k = 0; k < out.nodes; ++k) kept += weight[order[k]];
  for (int k = 0; k < out.nodes; ++k) {
    out.node[k] = node[order[k]];
    out.slot[k] = slot[order[k]];
    out.weight[k] = weight[order[k]] / kept;
  }
  if (gradient != nullptr) {
    // w_k = W_k / sum W over the kept nodes: dw_k = (dW_k - w_k sum dW) / sum W.
    mesh::Vec3 total_slope = mesh::Vec3::Zero();
    for (int k = 0; k < out.nodes; ++k) total_slope += slope[order[k]];
    for (int k = 0; k < out.nodes; ++k)
      (*gradient)[k] = (slope[order[k]] - out.weight[k] * total_slope) / kept;
  }
  return true;
}

}  // namespace neurosim::interaction
