#include "server/interaction/tool_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace neurosim::interaction {

namespace {
// 3 K(e) / (2 pi a) for semi-axes a, b (either order), unit 1/m: K(e) = pi / (2 AGM(1, b / a)).
double elliptic_approach(double a_m, double b_m) {
  const double major = std::max(a_m, b_m);
  double x = 1.0, y = std::min(a_m, b_m) / major;
  for (int i = 0; i < 40 && std::abs(x - y) > 1e-15 * x; ++i) {
    const double m = 0.5 * (x + y);
    y = std::sqrt(x * y);
    x = m;
  }
  return 3.0 / (4.0 * x * major);  // 3 (pi / (2 x)) / (2 pi major)
}
}  // namespace

namespace {
// The line of the exit-point construction (exit_normal): its direction a for the centre at d
// from the feature's point, and d a / d d. Radial (a = d / |d|) while d lies within the cone of
// half-angle alpha about m; outside it a at angle alpha (pi - theta) / (pi - alpha) from m
// towards d (theta the angle of d from m); m itself on a flat surface (alpha = 0), for d on m
// or at the point, and for a centre straight behind the feature.
void exit_line(const mesh::Vec3& d, const mesh::Vec3& m, double cos_alpha, double r,
               mesh::Vec3& a, Eigen::Matrix3d& da) {
  using Mat3 = Eigen::Matrix3d;
  const Mat3 id = Mat3::Identity();
  const double dn = d.norm();
  a = m;
  da.setZero();
  if (!(dn > 1e-9 * r)) return;
  const double ca = std::clamp(cos_alpha, -1.0, 1.0);
  const double alpha = std::acos(ca);
  const double c = std::clamp(d.dot(m) / dn, -1.0, 1.0);
  const double theta = std::acos(c);
  if (theta <= alpha && alpha > 0.0) {
    a = d / dn;
    da = (id - a * a.transpose()) / dn;
  } else if (theta > alpha) {
    const mesh::Vec3 side = d - d.dot(m) * m;
    const double sn = side.norm();
    const double phi = alpha * (M_PI - theta) / (M_PI - alpha);
    if (sn > 1e-12 * dn) {
      const mesh::Vec3 s = side / sn;
      a = std::cos(phi) * m + std::sin(phi) * s;
      if (alpha > 0.0) {
        // theta = acos(d . m / |d|): d theta / d d = -(m - c d / |d|) / |side| (sin theta = sn / dn).
        const mesh::Vec3 dtheta = -(m - c * d / dn) / sn;
        const mesh::Vec3 dphi = (-alpha / (M_PI - alpha)) * dtheta;
        const Mat3 ds = (id - s * s.transpose()) * (id - m * m.transpose()) / sn;
        da = (-std::sin(phi) * m + std::cos(phi) * s) * dphi.transpose() + std::sin(phi) * ds;
      }
    }
  }
}
}  // namespace

mesh::Vec3 exit_normal(const mesh::Vec3& d, const mesh::Vec3& m, double cos_alpha, double r) {
  mesh::Vec3 a;
  Eigen::Matrix3d da;
  exit_line(d, m, cos_alpha, r, a, da);
  const double along = a.dot(d);
  const double perp2 = std::max(0.0, d.squaredNorm() - along * along);
  if (perp2 < r * r) {
    const mesh::Vec3 v = d + (std::sqrt(r * r - perp2) - along) * a;
    const double vn = v.norm();
    if (vn > 0.0) return v / vn;
    return a;
  }
  return (d - along * a) / std::sqrt(perp2);
}

Eigen::Matrix3d exit_normal_turn(const mesh::Vec3& d, const mesh::Vec3& m, double cos_alpha,
                                 double r) {
  using Mat3 = Eigen::Matrix3d;
  const Mat3 id = Mat3::Identity();
  mesh::Vec3 a;
  Mat3 da;  // d a / d d
  exit_line(d, m, cos_alpha, r, a, da);
  const double along = a.dot(d);
  const mesh::Vec3 dalong = a + da.transpose() * d;  // gradient of a . d
  const double perp2 = std::max(0.0, d.squaredNorm() - along * along);
  if (perp2 < r * r) {
    const double q = std::sqrt(r * r - perp2);
    const mesh::Vec3 dq = -(d - along * dalong) / q;  // gradient of sqrt(r^2 - perp^2)
    const mesh::Vec3 v = d + (q - along) * a;
    const double vn = v.norm();
    if (!(vn > 0.0)) return Mat3::Zero();
    const mesh::Vec3 n = v / vn;
    const Mat3 dv = id + a * (dq - dalong).transpose() + (q - along) * da;
    return (id - n * n.transpose()) * dv / vn;
  }
  const mesh::Vec3 w = d - along * a;
  const double wn = std::sqrt(perp2);
  const mesh::Vec3 n = w / wn;
  const Mat3 dw = id - a * dalong.transpose() - along * da;
  return (id - n * n.transpose()) * dw / wn;
}

CapsuleExit capsule_exit(const mesh::Vec3& x, const mesh::Vec3& p0, const mesh::Vec3& p1,
                         const mesh::Vec3& m, double cos_alpha, double r,
                         Eigen::Matrix3d* dn_dx) {
  using Mat3 = Eigen::Matrix3d;
  const mesh::Vec3 axis = p1 - p0;
  const double len = axis.norm();
  CapsuleExit out;
  out.centre = closest_on_segment(x, p0, p1);
  const mesh::Vec3 d = out.centre - x;
  out.normal = exit_normal(d, m, cos_alpha, r);
  if (dn_dx) {
    // d d / d x = (u u^T inside the segment: the centre slides along the axis; else 0) - I.
    Mat3 slide = Mat3::Zero();
    if (len > 0.0) {
      const mesh::Vec3 u = axis / len;
      const double s = (x - p0).dot(u);
      if (s > 0.0 && s < len) slide = u * u.transpose();
    }
    *dn_dx = exit_normal_turn(d, m, cos_alpha, r) * (slide - Mat3::Identity());
  }
  return out;
}

double patch_near_field(double a_m, double b_m, double rho_m, double e_star_pa) {
  if (!(rho_m > 0.0) || !(a_m > 0.0) || !(b_m > 0.0)) return 0.0;
  constexpr double kQ = (0.766 / 0.75) * (0.766 / 0.75);
  const double s2 = rho_m * rho_m / kQ;
  const double shown = elliptic_approach(std::sqrt(a_m * a_m + s2), std::sqrt(b_m * b_m + s2));
  return std::max(0.0, (elliptic_approach(a_m, b_m) - shown) / e_star_pa);
}

void shaft_patch(double depth_m, double sin_tilt, double shaft_radius_m, double shaft_length_m,
                 double& a_m, double& b_m) {
  const double d = std::max(depth_m, 1e-4 * shaft_radius_m);
  b_m = std::sqrt(shaft_radius_m * std::min(d, shaft_radius_m));
  const double s = std::clamp(std::abs(sin_tilt), 0.0, 1.0);
  const double c = std::sqrt(1.0 - s * s);
  // d / (pi tan theta) = d cos / (pi sin), at most l_s / 2 (also as sin -> 0).
  const double half = 0.5 * std::max(shaft_length_m, 2.0 * b_m);
  const double along = d * c < M_PI * s * half ? d * c / (M_PI * s) : half;
  a_m = std::max(b_m, along);
}

PointGrid::PointGrid(const std::vector<mesh::Vec3>& points_m, double cell_m)
    : count_(static_cast<int>(points_m.size())) {
  if (!(cell_m > 0.0) || !std::isfinite(cell_m))
    throw std::invalid_argument("PointGrid: cell size must be > 0");
  if (points_m.empty()) return;
  mesh::Vec3 lo = points_m.front(), hi = points_m.front();
  for (const auto& p : points_m) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  // At most ~64 cells per axis: a surface grid, the query cost is in the per-node test.
  const double extent = (hi - lo).maxCoeff();
  cell_ = std::max(cell_m, extent / 64.0);
  origin_ = lo;
  for (int a = 0; a < 3; ++a)
    dims_[a] = std::max(1, static_cast<int>(std::floor((hi[a] - lo[a]) / cell_)) + 1);
  const int cells = dims_[0] * dims_[1] * dims_[2];
  std::vector<int> cell_of(points_m.size());
  offsets_.assign(cells + 1, 0);
  cell_of_.resize(points_m.size());
  for (std::size_t i = 0; i < points_m.size(); ++i) {
    auto& idx = cell_of_[i];
    for (int a = 0; a < 3; ++a)
      idx[a] = std::clamp(static_cast<int>(std::floor((points_m[i][a] - lo[a]) / cell_)), 0,
                          dims_[a] - 1);
    cell_of[i] = (idx[2] * dims_[1] + idx[1]) * dims_[0] + idx[0];
    ++offsets_[cell_of[i] + 1];
  }
  for (int c = 0; c < cells; ++c) offsets_[c + 1] += offsets_[c];
  items_.resize(points_m.size());
  rank_.resize(points_m.size());
  std::vector<int> fill(offsets_.begin(), offsets_.end() - 1);
  for (std::size_t i = 0; i < points_m.size(); ++i) {
    rank_[i] = fill[cell_of[i]]++;
    items_[rank_[i]] = static_cast<int>(i);
  }
}

PointGrid::CellRange PointGrid::cells(const mesh::Vec3& lo, const mesh::Vec3& hi) const {
  CellRange r;
  if (count_ == 0) return r;
  CellRange in;
  for (int a = 0; a < 3; ++a) {
    const double l = (lo[a] - origin_[a]) / cell_, h = (hi[a] - origin_[a]) / cell_;
    if (h < 0.0 || l >= dims_[a]) return r;
    in.lo[a] = std::max(0, static_cast<int>(std::floor(l)));
    in.hi[a] = std::min(dims_[a] - 1, static_cast<int>(std::floor(h)));
  }
  return in;
}

template <class Visit>
void PointGrid::visit_cells(const CellRange& box, bool has_near, const CellRange& near,
                            const mesh::Vec3& a, const mesh::Vec3& b, double radius,
                            Visit&& visit) const {
  if (!(radius >= 0.0)) throw std::invalid_argument("PointGrid: a query's radius must be >= 0");
  // The cells of both ranges in the grid's order (z, y, x), so the ranks come out ascending.
  CellRange all = box;
  if (has_near) {
    for (int k = 0; k < 3; ++k) {
      all.lo[k] = std::min(box.lo[k], near.lo[k]);
      all.hi[k] = std::max(box.hi[k], near.hi[k]);
    }
    const bool empty_box = box.hi[0] < box.lo[0] || box.hi[1] < box.lo[1] || box.hi[2] < box.lo[2];
    if (empty_box) all = near;
    if (near.hi[0] < near.lo[0] || near.hi[1] < near.lo[1] || near.hi[2] < near.lo[2]) {
      all = box;
      has_near = false;
    }
  }
  // A near cell is skipped when its centre is farther from the segment than radius plus the
  // cell's half diagonal (every point of the cell then farther than radius), with room for
  // rounding.
  const double half = 0.5 * std::sqrt(3.0) * cell_;
  const double bound = (radius + half) * (1.0 + 1e-9) + 1e-9 * cell_;
  const double bound2 = bound * bound;
  for (int z = all.lo[2]; z <= all.hi[2]; ++z)
    for (int y = all.lo[1]; y <= all.hi[1]; ++y)
      for (int x = all.lo[0]; x <= all.hi[0]; ++x) {
        const int c = (z * dims_[1] + y) * dims_[0] + x;
        if (offsets_[c] == offsets_[c + 1]) continue;
        const std::array<int, 3> at{x, y, z};
        if (!contains(box, at)) {
          if (!has_near || !contains(near, at)) continue;
          const mesh::Vec3 centre = origin_ + cell_ * mesh::Vec3(x + 0.5, y + 0.5, z + 0.5);
          if ((centre - closest_on_segment(centre, a, b)).squaredNorm() > bound2) continue;
        }
        visit(offsets_[c], offsets_[c + 1]);
      }
}

void PointGrid::query_near(const mesh::Vec3& lo, const mesh::Vec3& hi, const mesh::Vec3& a,
                           const mesh::Vec3& b, double radius, std::vector<int>& out) const {
  visit_cells(CellRange{}, true, cells(lo, hi), a, b, radius, [&](int first, int last) {
    for (int k = first; k < last; ++k) out.push_back(items_[k]);
  });
}

void PointGrid::query(const mesh::Vec3& lo, const mesh::Vec3& hi, std::vector<int>& out) const {
  visit_cells(cells(lo, hi), false, CellRange{}, lo, lo, 0.0, [&](int first, int last) {
    for (int k = first; k < last; ++k) out.push_back(items_[k]);
  });
}

void PointGrid::query_ranks(const mesh::Vec3& lo, const mesh::Vec3& hi, bool has_near,
                            const mesh::Vec3& near_lo, const mesh::Vec3& near_hi,
                            const mesh::Vec3& a, const mesh::Vec3& b, double radius,
                            std::vector<int>& ranks) const {
  visit_cells(cells(lo, hi), has_near, has_near ? cells(near_lo, near_hi) : CellRange{}, a, b,
              radius, [&](int first, int last) {
                for (int k = first; k < last; ++k) ranks.push_back(k);
              });
}

}  // namespace neurosim::interaction
