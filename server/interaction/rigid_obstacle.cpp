#include "server/interaction/rigid_obstacle.hpp"

#include "server/fusion/coupling_map.hpp"
#include "server/fusion/triangle_bvh.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

std::unique_ptr<const RigidObstacle> RigidObstacle::build(
    const std::vector<scene::RigidSurface>& surfaces, const RigidObstacleOptions& options) {
  if (surfaces.empty()) return nullptr;
  return std::make_unique<const RigidObstacle>(surfaces, options);
}

RigidObstacle::RigidObstacle(const std::vector<scene::RigidSurface>& surfaces,
                             const RigidObstacleOptions& options)
    : options_(options) {
  if (!(options.merge_cos > 0.0 && options.merge_cos <= 1.0))
    throw std::invalid_argument("RigidObstacleOptions::merge_cos must be in (0, 1]");
  if (!(options.shaft_box_length_m > 0.0 && std::isfinite(options.shaft_box_length_m)))
    throw std::invalid_argument("RigidObstacleOptions::shaft_box_length_m must be > 0");
  for (const auto& s : surfaces) {
    if (s.triangles.empty())
      throw std::invalid_argument("rigid surface \"" + s.id + "\" (" + s.file + ") has no triangles");
    const int base = static_cast<int>(vertices_m_.size());
    vertices_m_.insert(vertices_m_.end(), s.vertices_m.begin(), s.vertices_m.end());
    for (std::size_t t = 0; t < s.triangles.size(); ++t) {
      mesh::Tri tri = s.triangles[t];
      for (int& v : tri) {
        if (v < 0 || v >= static_cast<int>(s.vertices_m.size()))
          throw std::invalid_argument("rigid surface \"" + s.id + "\" (" + s.file + "): triangle " +
                                      std::to_string(t) + " has a vertex index out of range");
        v += base;
      }
      const mesh::Vec3 n = (vertices_m_[tri[1]] - vertices_m_[tri[0]])
                               .cross(vertices_m_[tri[2]] - vertices_m_[tri[0]]);
      if (!(n.norm() > 0.0))
        throw std::invalid_argument("rigid surface \"" + s.id + "\" (" + s.file + "): triangle " +
                                    std::to_string(t) + " is degenerate");
      triangles_.push_back(tri);
      face_normals_.push_back(n.normalized());
      const mesh::Vec3 c = (vertices_m_[tri[0]] + vertices_m_[tri[1]] + vertices_m_[tri[2]]) / 3.0;
      centroids_m_.push_back(c);
      bound_radii_m_.push_back(std::max({(vertices_m_[tri[0]] - c).norm(), (vertices_m_[tri[1]] - c).norm(),
                                         (vertices_m_[tri[2]] - c).norm()}));
    }
  }
  lo_m_ = hi_m_ = vertices_m_.front();
  for (const auto& v : vertices_m_) {
    lo_m_ = lo_m_.cwiseMin(v);
    hi_m_ = hi_m_.cwiseMax(v);
  }
  bvh_ = std::make_unique<fusion::TriangleBvh>(vertices_m_, triangles_);
}

RigidObstacle::~RigidObstacle() = default;

RigidObstacle::Scratch RigidObstacle::make_scratch() const {
  Scratch s;
  s.triangles.reserve(triangles_.size());
  s.stamp.assign(triangles_.size(), 0);
  s.candidates.reserve(triangles_.size());
  return s;
}

void RigidObstacle::collect(const mesh::Vec3& lo, const mesh::Vec3& hi, Scratch& s) const {
  bvh_->triangles_in_box(lo, hi, s.triangles);
}

void RigidObstacle::query(const ObstacleQuery& q, Scratch& s, ObstaclePlanes& out) const {
  out.count = 0;
  s.candidates.clear();
  const double r_tip = q.shape.tip_radius_m, r_shaft = q.shape.shaft_radius_m;
  const mesh::Vec3& x = q.free_tip_m;

  // A candidate: the closest point c of triangle t to the part point `part` (radius r, at
  // shaft_offset along the axis). The normal faces the free pose: (part - c) when the free pose
  // is known, so a tool that tunnelled through the shell is pushed back to where it came from.
  auto consider = [&](int t, const mesh::Vec3& part, const mesh::Vec3& c, double r,
                      double offset) {
    const mesh::Vec3 d = part - c;
    const double dist = d.norm();
    if (dist - r > q.reach_m) return;
    const mesh::Vec3& nf = face_normals_[static_cast<std::size_t>(t)];
    mesh::Vec3 n = nf;
    if (q.free_known && dist > 1e-12) {
      // The free part point sees this triangle from behind (through the bone): not its surface.
      // At an edge or vertex a neighbour with the same closest point faces it.
      if (d.dot(nf) < -1e-9 * dist) return;
      n = d / dist;
    }
    s.candidates.push_back(Candidate{dist - r, c, n, r, offset, t});
  };
  auto corner = [&](int t, int k) -> const mesh::Vec3& {
    return vertices_m_[static_cast<std::size_t>(triangles_[static_cast<std::size_t>(t)][k])];
  };

  // Tip sphere.
  s.triangles.clear();
  const mesh::Vec3 grow = mesh::Vec3::Constant(r_tip + q.reach_m);
  collect(x - grow, x + grow, s);
  for (int t : s.triangles) {
    const auto ti = static_cast<std::size_t>(t);
    if ((centroids_m_[ti] - x).norm() - bound_radii_m_[ti] > r_tip + q.reach_m) continue;
    consider(t, x, fusion::closest_point_on_triangle(x, corner(t, 0), corner(t, 1), corner(t, 2)).point_m,
             r_tip, 0.0);
  }

  // Shaft capsule, in boxes along it; each triangle once per query (the tip's triangles too:
  // their shaft points are the shaft's own constraints).
  const double len = q.shape.shaft_length_m;
  if (len > 0.0 && r_shaft > 0.0) {
    ++s.pass;
    const mesh::Vec3 g = mesh::Vec3::Constant(r_shaft + q.reach_m);
    const mesh::Vec3 s1 = x + len * q.axis;
    // Only the part of the shaft inside the obstacles' bounding box (grown by the reach) can
    // meet them: clip [0, len] to it (slabs), then search that part in boxes.
    double t0 = 0.0, t1 = len;
    const mesh::Vec3 blo = lo_m_ - g, bhi = hi_m_ + g;
    for (int a = 0; a < 3 && t0 <= t1; ++a) {
      const double d = q.axis[a];
      if (std::abs(d) < 1e-15) {
        if (x[a] < blo[a] || x[a] > bhi[a]) t1 = -1.0;
        continue;
      }
      double ta = (blo[a] - x[a]) / d, tb = (bhi[a] - x[a]) / d;
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
    const int pieces = t1 >= t0 ? std::max(1, static_cast<int>(std::ceil((t1 - t0) / options_.shaft_box_length_m))) : 0;
    for (int k = 0; k < pieces; ++k) {
      const mesh::Vec3 a = x + (t0 + (t1 - t0) * k / pieces) * q.axis;
      const mesh::Vec3 b = x + (t0 + (t1 - t0) * (k + 1) / pieces) * q.axis;
      s.triangles.clear();
      collect(a.cwiseMin(b) - g, a.cwiseMax(b) + g, s);
      for (int t : s.triangles) {
        const auto ti = static_cast<std::size_t>(t);
        auto& st = s.stamp[ti];
        if (st == s.pass) continue;
        st = s.pass;
        const mesh::Vec3& centroid = centroids_m_[ti];
        mesh::Vec3 p = closest_on_segment(centroid, x, s1);
        if ((centroid - p).norm() - bound_radii_m_[ti] > r_shaft + q.reach_m) continue;
        // Closest pair of segment and triangle (both convex) by alternating projections.
        mesh::Vec3 c = fusion::closest_point_on_triangle(p, corner(t, 0), corner(t, 1), corner(t, 2)).point_m;
        for (int it = 0; it < 6; ++it) {
          const mesh::Vec3 next = closest_on_segment(c, x, s1);
          const bool settled = (next - p).squaredNorm() < 1e-18;  // 1 nm
          p = next;
          if (settled) break;
          c = fusion::closest_point_on_triangle(p, corner(t, 0), corner(t, 1), corner(t, 2)).point_m;
        }
        consider(t, p, c, r_shaft, (p - x).dot(q.axis));
      }
    }
  }

  // Nearest first; a candidate nearly parallel to a kept plane is covered by it.
  std::sort(s.candidates.begin(), s.candidates.end(),
            [](const Candidate& a, const Candidate& b) {
              return a.gap_m < b.gap_m || (a.gap_m == b.gap_m && a.triangle < b.triangle);
            });
  for (const Candidate& c : s.candidates) {
    bool merged = false;
    for (int i = 0; i < out.count && !merged; ++i)
      merged = out.planes[static_cast<std::size_t>(i)].normal.dot(c.normal) >= options_.merge_cos;
    if (merged) continue;
    if (out.count == kMaxObstaclePlanes) break;
    ObstaclePlane& p = out.planes[static_cast<std::size_t>(out.count++)];
    p.normal = c.normal;
    p.surface_point_m = c.surface_point_m;
    p.point_m = c.surface_point_m + c.radius_m * c.normal - c.shaft_offset_m * q.axis;
    p.penetration_m = std::max(0.0, -c.normal.dot(q.tip_m - p.point_m));
    p.shaft_offset_m = c.shaft_offset_m;
    p.triangle = c.triangle;
  }
}

RigidObstacle::Closest RigidObstacle::closest(const mesh::Vec3& p) const {
  const auto c = bvh_->closest(p);
  return Closest{c.triangle, c.point_m, c.distance_m};
}

double RigidObstacle::winding_number(const mesh::Vec3& p) const {
  // Solid angle of each triangle seen from p (Van Oosterom and Strackee 1983), summed / 4 pi.
  double sum = 0.0;
  for (const auto& t : triangles_) {
    const mesh::Vec3 a = vertices_m_[t[0]] - p, b = vertices_m_[t[1]] - p, c = vertices_m_[t[2]] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum / (4.0 * M_PI);
}

}  // namespace neurosim::interaction
