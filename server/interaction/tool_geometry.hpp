// Tool shape against surface nodes: a spherical tip plus a capsule shaft, a uniform grid over
// the contactable nodes' rest positions for candidates, and the penetration depth of a node.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

namespace neurosim::interaction {

struct ToolShape {
  double tip_radius_m{0.0};
  double shaft_radius_m{0.0};
  double shaft_length_m{0.0};
};

// Depth (unit m) by which a node at x with outward normal n must move inward (along -n) to lie
// on the sphere (centre c, radius r) from the tissue side: the sphere's point on the node's
// normal line (Eq. "node penetration depth" of the contact rows). -inf when the normal line
// misses the sphere; <= 0 when the node is clear of it.
inline double normal_line_depth(const mesh::Vec3& x, const mesh::Vec3& n, const mesh::Vec3& c,
                                double r) {
  const mesh::Vec3 d = x - c;
  const double a = d.dot(n);
  const double perp2 = d.squaredNorm() - a * a;
  if (perp2 >= r * r) return -std::numeric_limits<double>::infinity();
  return a + std::sqrt(r * r - perp2);
}

// Height (unit m) of the node above the centre c along its outward normal n: how deep the
// centre is below the surface patch of the node.
inline double height_above(const mesh::Vec3& x, const mesh::Vec3& n, const mesh::Vec3& c) {
  return (x - c).dot(n);
}

// The normal of a node or edge row against the tip sphere (radius r, centre at d from the
// feature's point; LINEAR, contact_step.cpp merge_features): the sphere's outward normal where
// the point, moved along the line of direction a through it, leaves the sphere on the tissue's
// side (|d + t a| = r, the larger t); where that line misses the sphere, the direction from the
// line to the centre (perpendicular to a). The row's depth is then r - n . d, the depth of the
// sphere's tangent plane there (0 at the line's tangent point, continuous). The line: radial
// (a = d / |d|, so n = a and the depth r - |d|, the point against a rigid sphere) while the
// centre lies within the feature's normal cone, approximated as the cone of half-angle alpha
// about the mean normal m (cos alpha = |sum of the reporting triangles' unit normals| /
// their count: 1 on a flat surface, cos of half the dihedral angle at an edge); outside it the
// direction at angle alpha (pi - theta) / (pi - alpha) from m towards d (theta the angle of d
// from m): continuous in d, m itself for a centre straight behind the feature and for every
// centre over a flat surface. With a fixed along a press (a flat surface) n does not turn as
// the tip moves along m, so the flat-contact stiffness -N W^-1 N^T is the force's derivative.
mesh::Vec3 exit_normal(const mesh::Vec3& d, const mesh::Vec3& m, double cos_alpha, double r);

// The derivative of exit_normal in d (unit 1/m; the row's normal turn, d n = J d d): the same
// branches, differentiated in closed form. Radial (a = d / |d|): (I - n n^T) / |d|; along a fixed
// line a (a flat surface: a = m): n = (d + t a) / r, t = sqrt(r^2 - perp^2) - a . d, so
// J = (I - n n^T)(I + a (dt/dd)^T) / r, with the turn of a itself outside the cone (a's angle
// phi and side direction follow d's). A degenerate cone (cos alpha = 1) takes the fixed line
// also for d on m: the radial branch has no neighbourhood there. Zero where d is straight
// behind or on the feature (a = m held).
Eigen::Matrix3d exit_normal_turn(const mesh::Vec3& d, const mesh::Vec3& m, double cos_alpha,
                                 double r);

// The exit-point construction of exit_normal for the shaft, a capsule (axis p0 -> p1, radius r),
// against a node or edge point x (mean normal m, cone cos_alpha as exit_normal's): exit_normal
// against the capsule's sphere about c, the axis point closest to x (the capsule's cross-section
// through x: inside the segment x - c is across the axis), d = c - x. The row's depth is
// r - n . (centre - x) with centre = c. Where the line through x lies in that cross-section (a
// shaft lying on the surface) this is the capsule's own normal where the point, moved along the
// line, leaves it; radial while c is in the feature's cone (the point against a rigid capsule),
// turning continuously into the mean normal's line outside it: no switch where the axis crosses
// the feature's tangent plane. Not the ray-capsule exit: a line along the axis (a shaft piercing
// the surface) leaves the capsule only past the tip, so that depth is the shaft's length in the
// tissue (tried: a shaft driven through a block, K's normal turn 22 kN/m against the suite's
// 2.4 kN/m bound); the cross-section's sphere leaves it within 2 r. With dn_dx, d n / d x of the
// point with the capsule held (unit 1/m; the tool's translation t moves x relative to it by
// (dx/dt - I) t): exit_normal_turn times d d / d x = (u u^T inside the segment, else 0) - I.
struct CapsuleExit {
  mesh::Vec3 normal{mesh::Vec3::Zero()};
  mesh::Vec3 centre{mesh::Vec3::Zero()};
};
CapsuleExit capsule_exit(const mesh::Vec3& x, const mesh::Vec3& p0, const mesh::Vec3& p1,
                         const mesh::Vec3& m, double cos_alpha, double r,
                         Eigen::Matrix3d* dn_dx = nullptr);

// Closest point of segment [p0, p1] to x.
inline mesh::Vec3 closest_on_segment(const mesh::Vec3& x, const mesh::Vec3& p0,
                                     const mesh::Vec3& p1) {
  const mesh::Vec3 e = p1 - p0;
  const double len2 = e.squaredNorm();
  if (len2 == 0.0) return p0;
  const double t = std::clamp((x - p0).dot(e) / len2, 0.0, 1.0);
  return p0 + t * e;
}

// The near field of a contact patch under a mesh that spreads each row's load over a disk of
// radius rho (SimulationOptions::contact_near_field; unit m/N): the approach compliance of the
// true patch less that of the patch as the mesh shows it. A rigid indenter on a half-space with
// an elliptic patch of semi-axes a, b (Hertz's elliptic contact, Johnson, Contact Mechanics,
// 4.2: delta = p0 b K(e) / E*, p0 = 3 F / (2 pi a b), a >= b) has the secant compliance
// 3 K(e) / (2 pi a E*), K the complete elliptic integral of the first kind, e^2 = 1 - b^2 / a^2
// (the circle: 0.75 / (a E*), Hertz's; a long patch: 3 ln(4 a / b) / (2 pi a E*), the finite
// line contact). The mesh's rows carry the patch's load spread about each point: mean square
// radii add, so the patch it shows has semi-axes sqrt(a^2 + rho^2 / q), sqrt(b^2 + rho^2 / q),
// q = (0.766 / 0.75)^2 as the tip's (contact_step.cpp near_field_of_tool, which this is for
// a = b: 0.75 / sqrt(a^2 + rho^2 / q) = 0.766 / sqrt(rho^2 + q a^2)). Clamped at 0; 0 without
// a spread (rho = 0: the rows sample the patch themselves). e_star = E / (1 - nu^2), unit Pa.
double patch_near_field(double a_m, double b_m, double rho_m, double e_star_pa);

// The shaft's patch (a capsule of radius r_s and length l_s) whose deepest row is d deep
// (unit m) under a surface whose normal makes sin_tilt = |n . axis| with the axis: across the
// axis b = sqrt(r_s min(d, r_s)) (Hertz's a = sqrt(R d) with the cylinder's radius, bounded by
// it); along the axis the capsule's lowest line is tilted by theta to the surface and under it
// over d / tan(theta) from the deepest point: a wedge, whose contact covers 2 / pi of its
// geometric reach (Sneddon's cone, a = (2 / pi) delta tan(alpha), the linear profile's as Hertz's
// 1 / sqrt(2) is the parabola's), a = d / (pi tan(theta)) as a semi-axis, between b (the
// capsule's round end) and l_s / 2 (a shaft lying on the surface). Sets the semi-axes (unit m).
void shaft_patch(double depth_m, double sin_tilt, double shaft_radius_m, double shaft_length_m,
                 double& a_m, double& b_m);

// Uniform grid over points (rest positions of contactable nodes): box queries return point
// indices in ascending order of cell then insertion (deterministic), into a caller's vector.
class PointGrid {
 public:
  PointGrid() = default;
  PointGrid(const std::vector<mesh::Vec3>& points_m, double cell_m);
  // Appends the indices of points in cells overlapping [lo, hi] (a superset of the points in it).
  void query(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const;
  // As query(lo, hi) without the cells wholly farther than radius from the segment [a, b]: the
  // same points in the same order less some, every point within radius of the segment kept (a
  // long tilted shaft's box holds far more of the surface than its capsule).
  void query_near(const mesh::Vec3& lo, const mesh::Vec3& hi, const mesh::Vec3& a,
                  const mesh::Vec3& b, double radius, std::vector<int>& out) const;
  // The union of query(lo, hi) and query_near(near_lo, near_hi, a, b, radius) with each point
  // once, as ranks (ascending: the grid's order; item(rank) is the point). Without a second box
  // (has_near false) it is query(lo, hi)'s ranks.
  void query_ranks(const mesh::Vec3& lo, const mesh::Vec3& hi, bool has_near,
                   const mesh::Vec3& near_lo, const mesh::Vec3& near_hi, const mesh::Vec3& a,
                   const mesh::Vec3& b, double radius, std::vector<int>& ranks) const;
  int item(int rank) const { return items_[rank]; }
  bool empty() const { return count_ == 0; }
  // The cells query(lo, hi) visits (per axis lo..hi; none when some hi < lo), whether point i
  // lies in one of them, and its rank in the grid's order: a query lists its points by rank.
  struct CellRange {
    int lo[3]{0, 0, 0};
    int hi[3]{-1, -1, -1};
  };
  CellRange cells(const mesh::Vec3& lo, const mesh::Vec3& hi) const;
  bool contains(const CellRange& r, int i) const { return contains(r, cell_of_[i]); }
  // The same with point i's cell (cell(i)) kept by the caller (a list scanned per step).
  static bool contains(const CellRange& r, const std::array<int, 3>& c) {
    // (without branches: a scanned list's cells are in and out of the range in no pattern)
    return (c[0] >= r.lo[0]) & (c[0] <= r.hi[0]) & (c[1] >= r.lo[1]) & (c[1] <= r.hi[1]) &
           (c[2] >= r.lo[2]) & (c[2] <= r.hi[2]);
  }
  const std::array<int, 3>& cell(int i) const { return cell_of_[i]; }
  int rank(int i) const { return rank_[i]; }

 private:
  // Calls visit(first, last) for the rank ranges [first, last) of the cells in `box` and of the
  // cells in `near` not wholly farther than radius from the segment [a, b] (none without
  // has_near), each cell once, in the grid's order. Defined and used in tool_geometry.cpp.
  template <class Visit>
  void visit_cells(const CellRange& box, bool has_near, const CellRange& near, const mesh::Vec3& a,
                   const mesh::Vec3& b, double radius, Visit&& visit) const;

  mesh::Vec3 origin_{mesh::Vec3::Zero()};
  double cell_{1.0};
  int dims_[3]{0, 0, 0};
  int count_{0};
  std::vector<int> offsets_;  // CSR per cell
  std::vector<int> items_;
  std::vector<std::array<int, 3>> cell_of_;  // per point: its cell
  std::vector<int> rank_;                 // per point: its index in items_
};

}  // namespace neurosim::interaction
