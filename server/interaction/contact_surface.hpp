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
// Inline, always: the step calls it for every candidate feature and every round of the shaft's
// projections (its answer kept in registers; called out of line it came back through memory).
[[gnu::always_inline]] inline TrianglePoint closest_on_triangle(const mesh::Vec3& x, const std::array<mesh::Vec3, 3>& p) {
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

// Projection of x onto the triangle p along the normal field interpolated from its nodes' normals
// nn (N(u, v) = sum b_k nn_k, b the barycentric weights): the point y = sum b_k p_k with x - y
// parallel to N(y) (Newton on (u, v, height), from the flat projection). The field is the same
// on both sides of a shared edge, so the projection, its normal and the height of x above it are
// continuous as x moves across edges and creases (a smooth contact surface over the flat
// triangles: Phong's normals, the "averaged normal" projection of mortar contact). True with the
// point (feature kFace, weights b), its unit normal N / |N| and the signed height of x along it
// when the projection lies in the triangle (b >= -1e-12); false otherwise. The height is
// measured to the flat triangle along the tilted normal: over a convex ridge the tip sees less
// depth than the flat triangle's perpendicular one (a curved surface lifted to Phong
// tessellation's there was tried and dropped: on the 7 mm brain it sank concave places by up to
// a millimetre, 0.3 mN for a 1 mm press).
bool project_along_normals(const mesh::Vec3& x, const std::array<mesh::Vec3, 3>& p,
                           const std::array<mesh::Vec3, 3>& nn, TrianglePoint& at,
                           mesh::Vec3& unit_normal, double& height_m);

// One contactable triangle: host node ids (outward orientation), their contact slots (-1: a fixed
// node, which never moves), and per edge k (local vertices k, k+1) the number of contactable
// triangles that share it.
struct SurfaceTriangle {
  std::array<int, 3> node{};
  std::array<int, 3> slot{};
  std::array<int, 3> edge_triangles{};
};

// A unit load spread over the surface around a point: per node (host id, contact slot or -1 for
// a fixed node) its consistent weight (ContactSurface::spread), the weights summing to 1. At most
// kSpreadNodes (the largest weights kept): 32, since the tip's spread floor (5/3 of its radius,
// contact_step.cpp tip_spread_floor_m) covers 20-25 nodes of cells about the tip's radius; with
// 16, the 1 mm tip on 1 mm cells had K's lateral columns 2-25 % of s off the force's central
// differences at face points (tests/server/interaction/contact_step_test.cpp
// TipStiffnessIsTheForceDerivative; with 32 at most 1e-10).
inline constexpr int kSpreadNodes = 32;
struct SpreadLoad {
  int nodes{0};
  std::array<int, kSpreadNodes> node{};
  std::array<int, kSpreadNodes> slot{};
  std::array<double, kSpreadNodes> weight{};
  int dropped{0};  // nodes beyond kSpreadNodes (the smallest weights), left out
};

struct ContactSurfaceDefinition {
  const mesh::TetMesh* host{nullptr};
  const std::vector<int>* contact_slot{nullptr};  // per host node: contact slot or -1
  const std::vector<int>* fixed_nodes{nullptr};   // sorted host node ids
  // Optional: host faces covered by an embedded mesh (node triples, each sorted, sorted;
  // CoupledBody::covered_faces): never contactable, whatever their nodes' slots.
  const std::vector<std::array<int, 3>>* covered_faces{nullptr};
};

class ContactSurface {
 public:
  ContactSurface() = default;
  explicit ContactSurface(const ContactSurfaceDefinition& def);

  const std::vector<SurfaceTriangle>& triangles() const { return triangles_; }
  // Appends the triangles whose rest bounding sphere may reach the box [lo, hi] (a superset).
  void query(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const;
  // As query(lo, hi) less triangles far from the segment [a, b]: the same triangles in the same
  // order less some, every triangle whose centroid is within (reach + the largest bounding
  // radius) (1 + 1e-6) of the segment kept (unit m).
  void query_near(const mesh::Vec3& lo, const mesh::Vec3& hi, const mesh::Vec3& a,
                  const mesh::Vec3& b, double reach_m, std::vector<int>& out) const;
  // A tool's candidates as ranks (ascending, each once; ranked_triangle(rank) is the triangle):
  // the union of query(lo, hi) and, with has_near, query_near(near_lo, near_hi, a, b, near_m),
  // less the triangles whose rest bounding sphere is farther than sphere_m from the segment
  // [a, b] (kept: centroid within (radius + sphere_m) (1 + 1e-6) of it). The sphere test reads
  // the centroids and radii in rank order (a long shaft's boxes list far more triangles than
  // reach it). Unit m.
  void query_tool(const mesh::Vec3& lo, const mesh::Vec3& hi, bool has_near,
                  const mesh::Vec3& near_lo, const mesh::Vec3& near_hi, const mesh::Vec3& a,
                  const mesh::Vec3& b, double near_m, double sphere_m,
                  std::vector<int>& ranks) const;
  int ranked_triangle(int rank) const { return grid_.item(rank); }
  // The grid cells query(lo, hi) visits, whether triangle t is among the triangles they list,
  // and t's rank in a query's order (by rank; PointGrid).
  PointGrid::CellRange query_cells(const mesh::Vec3& lo, const mesh::Vec3& hi) const;
  bool listed(const PointGrid::CellRange& r, int t) const { return grid_.contains(r, t); }
  int query_rank(int t) const { return grid_.rank(t); }
  // Triangle t's grid cell (listed_cell: `listed` with it, the cell kept in the caller's list).
  const std::array<int, 3>& query_cell(int t) const { return grid_.cell(t); }
  static bool listed_cell(const PointGrid::CellRange& r, const std::array<int, 3>& cell) {
    return PointGrid::contains(r, cell);
  }
  // Rest centroid and the largest centroid-vertex distance over all triangles, unit m.
  const mesh::Vec3& centroid(int t) const { return centroid_[t]; }
  // Largest centroid-vertex distance of triangle t (rest), unit m.
  double radius_m(int t) const { return radius_m_[t]; }
  double max_radius_m() const { return max_radius_m_; }
  double mean_edge_m() const { return mean_edge_m_; }
  // Local edge length at the point with barycentric weights `bary` of triangle t: the weights'
  // blend of its nodes' mean incident edge lengths (continuous across edges), unit m.
  double edge_at_m(int t, const std::array<double, 3>& bary) const;
  // Rest vertices of triangle t, unit m, and its rest unit normal (zero for a degenerate
  // triangle): (x1 - x0) x (x2 - x0) normalized, the same values the contact step forms from the
  // host's vertices, so a step on the rest surface reads them instead.
  const std::array<mesh::Vec3, 3>& rest_vertices(int t) const { return rest_m_[t]; }
  const mesh::Vec3& rest_normal(int t) const { return normal_[t]; }
  // Rest unit normals of triangle t's nodes (area-weighted over the contactable triangles).
  const std::array<mesh::Vec3, 3>& node_normals(int t) const { return node_normal_[t]; }
  // The consistent nodal weights of a unit load spread around the rest point p with the pressure
  // k(s) = (1 - s^2 / rho^2)^2 for s = |y - p| < rho (s in space: a ball about p cut by the
  // surface), over the rest triangles facing the same side as n (n . n_t > 0: not the far wall of
  // a fold): w_a = int k phi_a dA / int k dA, integrated on each triangle by the midpoint rule on
  // its regular subdivision into at least (3 h_t / rho)^2 triangles (at most 8 per edge). The
  // kernel is C1 and vanishes at rho, so the weights change continuously with p. Fills `out`
  // (the largest kSpreadNodes weights, renormalized); `scratch` holds candidate triangles (its
  // capacity should be the triangle count: no allocation). False when no facing triangle lies
  // within rho (out unchanged). With `gradient`: per node of `out` d weight / d p (unit 1/m),
  // the node set and rho held (the kernel's derivative on the same samples, renormalized).
  bool spread(const mesh::Vec3& p, const mesh::Vec3& n, double rho_m, std::vector<int>& scratch,
              SpreadLoad& out,
              std::array<mesh::Vec3, kSpreadNodes>* gradient = nullptr) const;

 private:
  std::vector<SurfaceTriangle> triangles_;
  std::vector<mesh::Vec3> centroid_;
  std::vector<double> radius_m_;
  std::vector<std::array<mesh::Vec3, 3>> rest_m_;      // per triangle: its rest vertices
  std::vector<mesh::Vec3> normal_;                      // per triangle: rest unit normal
  std::vector<std::array<double, 3>> node_edge_m_;     // per triangle node: mean incident edge
  std::vector<std::array<mesh::Vec3, 3>> node_normal_;  // per triangle node: rest unit normal
  std::vector<double> spread_area_m2_;                  // per triangle: rest area (spread)
  std::vector<double> spread_longest_m_;                // per triangle: longest rest edge (spread)
  PointGrid grid_;
  std::vector<std::array<double, 4>> ranked_sphere_;  // per grid rank: centroid, radius (m)
  double max_radius_m_{0.0};
  double mean_edge_m_{0.0};
};

}  // namespace neurosim::interaction
