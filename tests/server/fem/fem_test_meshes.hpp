// Test-only structured tetrahedral meshes: a box of nx*ny*nz hexahedra, each split into the 6
// Kuhn tetrahedra around its main diagonal (conforming across hexahedra), optionally with the
// interior nodes jittered to make an irregular mesh; a clamped cantilever beam on it; random
// displacements from a seed.
#pragma once

#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace neurosim::fem::testing {

struct BoxSpec {
  int nx{1}, ny{1}, nz{1};                   // hexahedra per axis
  Eigen::Vector3d lo{0, 0, 0}, hi{1, 1, 1};  // unit m
  double jitter{0.0};  // interior nodes moved by up to jitter * cell size per axis
  unsigned seed{1};
};

inline int box_node(const BoxSpec& s, int i, int j, int k) {
  return i + (s.nx + 1) * (j + (s.ny + 1) * k);
}

inline mesh::TetMesh box_mesh(const BoxSpec& s) {
  std::vector<mesh::Vec3> x;
  const Eigen::Vector3d h((s.hi - s.lo).x() / s.nx, (s.hi - s.lo).y() / s.ny,
                          (s.hi - s.lo).z() / s.nz);
  std::mt19937 rng(s.seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k <= s.nz; ++k) {
    for (int j = 0; j <= s.ny; ++j) {
      for (int i = 0; i <= s.nx; ++i) {
        Eigen::Vector3d p = s.lo + Eigen::Vector3d(i * h.x(), j * h.y(), k * h.z());
        const bool interior = i > 0 && i < s.nx && j > 0 && j < s.ny && k > 0 && k < s.nz;
        if (interior && s.jitter > 0.0) {
          p += s.jitter * Eigen::Vector3d(u(rng) * h.x(), u(rng) * h.y(), u(rng) * h.z());
        }
        x.push_back(p);
      }
    }
  }
  // Kuhn: one tetrahedron per axis permutation, path 000 -> 111 along the permuted axes.
  static constexpr int kPerm[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2},
                                      {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  std::vector<mesh::Tet> tets;
  for (int k = 0; k < s.nz; ++k) {
    for (int j = 0; j < s.ny; ++j) {
      for (int i = 0; i < s.nx; ++i) {
        for (const auto& p : kPerm) {
          std::array<int, 3> c{i, j, k};
          mesh::Tet t;
          t[0] = box_node(s, c[0], c[1], c[2]);
          for (int step = 0; step < 3; ++step) {
            ++c[p[step]];
            t[step + 1] = box_node(s, c[0], c[1], c[2]);
          }
          if (mesh::signed_volume(x[t[0]], x[t[1]], x[t[2]], x[t[3]]) < 0.0) {
            std::swap(t[2], t[3]);
          }
          tets.push_back(t);
        }
      }
    }
  }
  mesh::BuildOptions opt;
  opt.source =
      "test box " + std::to_string(s.nx) + "x" + std::to_string(s.ny) + "x" + std::to_string(s.nz);
  return mesh::TetMesh::build(std::move(x), std::move(tets), opt);
}

// Nodes with pred(position) true.
inline std::vector<int> nodes_where(const mesh::TetMesh& m,
                                    const std::function<bool(const Eigen::Vector3d&)>& pred) {
  std::vector<int> out;
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    if (pred(m.vertices()[v])) {
      out.push_back(static_cast<int>(v));
    }
  }
  return out;
}

// A cantilever: 10 x 2 x 2 hexahedra over 0.1 x 0.02 x 0.02 m, clamped at x = 0 (`fixed`), the
// nodes of the free end x = 0.1 m in `tip`.
struct Beam {
  mesh::TetMesh mesh;
  std::vector<int> fixed;
  std::vector<int> tip;
  // total_n (N) spread evenly over the tip nodes, along -z.
  Eigen::VectorXd tip_load(double total_n) const {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(mesh.num_vertices()));
    for (int v : tip) f[3 * v + 2] = -total_n / static_cast<double>(tip.size());
    return f;
  }
};

inline Beam beam() {
  Beam b{box_mesh({10, 2, 2, {0, 0, 0}, {0.1, 0.02, 0.02}, 0.0, 1}), {}, {}};
  b.fixed = nodes_where(b.mesh, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  b.tip = nodes_where(b.mesh, [](const Eigen::Vector3d& p) { return p.x() > 0.1 - 1e-9; });
  return b;
}

// Every dof of m displaced by a uniform random value in [-amplitude_m, amplitude_m] (unit m),
// from a fixed seed.
inline Eigen::VectorXd random_displacement(const mesh::TetMesh& m, double amplitude_m,
                                           unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::VectorXd d(3 * static_cast<Eigen::Index>(m.num_vertices()));
  for (Eigen::Index i = 0; i < d.size(); ++i) d[i] = amplitude_m * u(rng);
  return d;
}

// max |a - b| / max |b|
inline double rel_max_diff(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

}  // namespace neurosim::fem::testing
