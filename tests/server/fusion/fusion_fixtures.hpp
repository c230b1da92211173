// Meshes and independent checks for the fusion tests: structured (Kuhn) boxes whose faces
// line up exactly with each other, rigid transforms, and a winding-number inside test that
// shares no code with the library's exact parity test.
#pragma once

#include "server/fusion/triangle_surface.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Geometry>

#include <cmath>
#include <random>
#include <vector>

namespace neurosim::fusion::test {

using mesh::TetMesh;
using mesh::Vec3;

// Box [lo, hi] split in nx*ny*nz cells, 6 tetrahedra per cell around the cell diagonal
// (conforming: every cell is cut the same way).
inline TetMesh structured_box(const Vec3& lo, const Vec3& hi, int nx, int ny, int nz) {
  std::vector<Vec3> v;
  auto id = [&](int i, int j, int k) { return (k * (ny + 1) + j) * (nx + 1) + i; };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i)
        v.emplace_back(lo.x() + (hi.x() - lo.x()) * i / nx, lo.y() + (hi.y() - lo.y()) * j / ny,
                       lo.z() + (hi.z() - lo.z()) * k / nz);
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::vector<mesh::Tet> tets;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        for (const auto& p : perms) {
          int c[3] = {i, j, k};
          mesh::Tet t{};
          t[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[s + 1] = id(c[0], c[1], c[2]);
          }
          tets.push_back(t);
        }
  mesh::BuildOptions o;
  o.source = "structured box";
  return TetMesh::build(std::move(v), std::move(tets), o);
}

// x -> scale * R x + t, same connectivity.
inline TetMesh transformed(const TetMesh& m, const Eigen::Matrix3d& r, double scale,
                           const Vec3& t) {
  std::vector<Vec3> v;
  v.reserve(m.num_vertices());
  for (const Vec3& x : m.vertices()) v.push_back(scale * (r * x) + t);
  mesh::BuildOptions o;
  o.source = m.source() + " (moved)";
  return TetMesh::build(std::move(v), m.tets(), o);
}

inline Eigen::Matrix3d random_rotation(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  return q.toRotationMatrix();
}

// Generalized winding number of a closed, outward-oriented surface at p (1 inside, 0 outside);
// Van Oosterom & Strackee solid angles. Reliable away from the surface.
inline double winding_number(const Vec3& p, const TriangleSurface& s) {
  double sum = 0.0;
  for (const auto& t : s.triangles) {
    const Vec3 a = s.vertices_m[t[0]] - p, b = s.vertices_m[t[1]] - p, c = s.vertices_m[t[2]] - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum / (4.0 * M_PI);
}

// Longest edge of tetrahedron t (m).
inline double longest_edge(const TetMesh& m, int t) {
  const auto& tet = m.tets()[t];
  double h = 0.0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j)
      h = std::max(h, (m.vertices()[tet[i]] - m.vertices()[tet[j]]).norm());
  return h;
}

// Tetrahedron of m containing p (barycentric >= -tol), or the one with the nearest centroid.
inline int locate(const TetMesh& m, const Vec3& p) {
  int best = -1;
  double best_d = 1e300;
  for (std::size_t t = 0; t < m.num_tets(); ++t) {
    const auto& tet = m.tets()[t];
    const Vec3& a = m.vertices()[tet[0]];
    Eigen::Matrix3d e;
    e.col(0) = m.vertices()[tet[1]] - a;
    e.col(1) = m.vertices()[tet[2]] - a;
    e.col(2) = m.vertices()[tet[3]] - a;
    const Vec3 l = e.fullPivLu().solve(p - a);
    if (l.minCoeff() >= -1e-9 && l.sum() <= 1.0 + 1e-9) return static_cast<int>(t);
    const Vec3 c = a + e * Vec3(0.25, 0.25, 0.25);
    if ((c - p).norm() < best_d) {
      best_d = (c - p).norm();
      best = static_cast<int>(t);
    }
  }
  return best;
}

}  // namespace neurosim::fusion::test
