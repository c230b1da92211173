// Small meshes built in code for the mesh tests.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <array>
#include <vector>

namespace neurosim::mesh::testing {

struct Arrays {
  std::vector<Vec3> vertices;
  std::vector<Tet> tets;
};

// Cube [0, n*h]^3 of n^3 cells, each split into 6 Kuhn tetrahedra (conforming), all positive.
inline Arrays grid_cube(int n, double h) {
  Arrays a;
  auto id = [n](int i, int j, int k) { return i + (n + 1) * (j + (n + 1) * k); };
  for (int k = 0; k <= n; ++k)
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) a.vertices.emplace_back(i * h, j * h, k * h);
  const std::array<std::array<int, 3>, 6> paths{
      {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}}};
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        for (const auto& p : paths) {
          // Walk from corner (i,j,k) to (i+1,j+1,k+1) one axis at a time.
          std::array<int, 3> c{i, j, k};
          Tet t;
          t[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[s + 1] = id(c[0], c[1], c[2]);
          }
          const auto& v = a.vertices;
          if (signed_volume(v[t[0]], v[t[1]], v[t[2]], v[t[3]]) < 0) std::swap(t[2], t[3]);
          a.tets.push_back(t);
        }
  return a;
}

inline Arrays single_tet() {
  return {{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)}, {Tet{0, 1, 2, 3}}};
}

// Volume enclosed by a closed triangle surface (divergence theorem): sum over triangles of
// (a-o).((b-o) x (c-o))/6, positive when the normals point outward. The origin o is outside
// the bounding box and off every face plane of the test meshes, so each face counts.
inline double enclosed_volume(const std::vector<Vec3>& v, const std::vector<Tri>& surface) {
  Vec3 lo = v.front(), hi = v.front();
  for (const Vec3& p : v) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  const Vec3 o = lo + (hi - lo).cwiseProduct(Vec3(-0.37, 1.91, -2.3));
  double vol = 0.0;
  for (const Tri& t : surface) vol += (v[t[0]] - o).dot((v[t[1]] - o).cross(v[t[2]] - o)) / 6.0;
  return vol;
}

}  // namespace neurosim::mesh::testing
