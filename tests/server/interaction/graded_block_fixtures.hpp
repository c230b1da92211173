// Test fixtures: blocks meshed on a structured grid graded away from a fine region (six Kuhn
// tetrahedra per cell), for presses whose contact patch must span several elements (the Hertz and
// CalculiX references, the mesh convergence of the contact force).
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <algorithm>
#include <array>
#include <utility>
#include <vector>

namespace neurosim::interaction::testing {

// Node coordinates of one axis, symmetric about 0: cells of `fine_m` out to `fine_half_m`, then
// each cell `growth` times the last until `half_m` is passed (the last node at the total).
inline std::vector<double> graded_axis(double fine_m, double fine_half_m, double growth,
                                       double half_m, bool symmetric) {
  std::vector<double> side{0.0};
  double h = fine_m;
  while (side.back() < fine_half_m - 1e-12) side.push_back(side.back() + fine_m);
  while (side.back() < half_m - 1e-12) {
    h *= growth;
    side.push_back(side.back() + h);
  }
  std::vector<double> out;
  if (symmetric)
    for (std::size_t k = side.size() - 1; k > 0; --k) out.push_back(-side[k]);
  out.insert(out.end(), side.begin(), side.end());
  return out;
}

// As graded_axis, but the last node exactly at `half_m` whatever the cell sizes (the graded
// cells scaled to end there), so that meshes of different fine sizes fill the same domain.
inline std::vector<double> graded_axis_to(double fine_m, double fine_half_m, double growth,
                                          double half_m, bool symmetric) {
  std::vector<double> side{0.0};
  while (side.back() < fine_half_m - 1e-12) side.push_back(side.back() + fine_m);
  const double fine_end = side.back();
  double h = fine_m;
  std::vector<double> graded;  // cell sizes beyond the fine region
  double reach = fine_end;
  while (reach < half_m - 1e-12) {
    h *= growth;
    graded.push_back(h);
    reach += h;
  }
  // Drop the last cell if the sum overshoots by more than half of it, then scale to end at half_m.
  if (graded.size() > 1 && reach - half_m > 0.5 * graded.back()) {
    reach -= graded.back();
    graded.pop_back();
  }
  const double scale = (half_m - fine_end) / (reach - fine_end);
  for (double g : graded) side.push_back(side.back() + scale * g);
  side.back() = half_m;
  std::vector<double> out;
  if (symmetric)
    for (std::size_t k = side.size() - 1; k > 0; --k) out.push_back(-side[k]);
  out.insert(out.end(), side.begin(), side.end());
  return out;
}

// Block [xs.front(), xs.back()]^2 x [-zs.back(), 0] (top face z = 0), six Kuhn tetrahedra per
// grid cell (every cell split along its (0, 0, 0)-(1, 1, 1) diagonal: the top face of a cell is
// split along its (i, j)-(i + 1, j + 1) diagonal).
inline mesh::TetMesh graded_block(const std::vector<double>& xs, const std::vector<double>& zs) {
  const int n = static_cast<int>(xs.size()), nz = static_cast<int>(zs.size());
  auto node = [&](int i, int j, int k) { return i + n * (j + n * k); };
  std::vector<mesh::Vec3> x;
  x.reserve(static_cast<std::size_t>(n) * n * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) x.emplace_back(xs[i], xs[j], -zs[nz - 1 - k]);
  static constexpr int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                      {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::vector<mesh::Tet> tets;
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i)
        for (const auto& p : kPerm) {
          std::array<int, 3> c{i, j, k};
          mesh::Tet t;
          t[0] = node(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[p[s]];
            t[s + 1] = node(c[0], c[1], c[2]);
          }
          if (mesh::signed_volume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]) < 0.0) std::swap(t[2], t[3]);
          tets.push_back(t);
        }
  mesh::BuildOptions opt;
  opt.source = "graded block";
  return mesh::TetMesh::build(std::move(x), std::move(tets), opt);
}

}  // namespace neurosim::interaction::testing
