// A host box A (40 mm, fixed at z = 0) with a floating box B (20 mm) tied to A's top face, and
// the reference answer: the monolithic tied system [K_A 0 -C_A^T; 0 K_B C_B^T; -C_A C_B 0]
// (C: u_B,k - sum_a w_a u_A,h_a = 0 for every surface node k of B) assembled here and solved
// directly (dense LU), independent of the Woodbury/condensation path of CoupledBody.
#pragma once

#include "server/fem/assembly.hpp"
#include "server/interaction/contact_surface.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/mesh/generate.hpp"

#include <Eigen/Dense>

#include <array>
#include <memory>
#include <vector>

namespace neurosim::interaction::tied_box {

struct TiedBox {
  mesh::TetMesh host;
  mesh::TetMesh embedded;  // def.embedded points here: never copied
  fem::Material host_material;
  std::vector<int> host_fixed;
  TieDefinition def;
};

// B's surface nodes are tied to A's top-face triangles in turn with fixed weights (the map is
// algebraic: the test checks the tied system, not the geometry of the map).
inline std::unique_ptr<const TiedBox> make_tied_box() {
  auto owner = std::make_unique<TiedBox>();
  TiedBox& c = *owner;
  mesh::MeshingOptions o;
  o.cell_size_m = 0.01;
  o.seed = 1;
  c.host = mesh::generate_box({0, 0, 0}, {0.04, 0.04, 0.04}, o).mesh;
  c.embedded = mesh::generate_box({0.01, 0.01, 0.04}, {0.03, 0.03, 0.06}, o).mesh;
  for (std::size_t v = 0; v < c.host.num_vertices(); ++v)
    if (c.host.vertices()[v].z() < 1e-9) c.host_fixed.push_back(static_cast<int>(v));
  c.host_material.youngs_modulus_pa = 3000.0;
  c.host_material.poisson_ratio = 0.45;
  c.host_material.name = "host";
  c.def.mesh = 1;
  c.def.embedded = &c.embedded;
  c.def.material.youngs_modulus_pa = 9000.0;  // stiffer than A: the tie matters
  c.def.material.poisson_ratio = 0.40;
  c.def.material.name = "embedded";
  std::vector<mesh::Tri> top;
  for (const auto& t : c.host.surface()) {
    bool on_top = true;
    for (int v : t) on_top = on_top && c.host.vertices()[v].z() > 0.04 - 1e-9;
    if (on_top) top.push_back(t);
  }
  const std::array<std::array<double, 3>, 3> weights{
      {{0.2, 0.3, 0.5}, {0.5, 0.25, 0.25}, {1.0 / 3, 1.0 / 3, 1.0 / 3}}};
  const auto& surface = c.embedded.surface_vertices();
  for (std::size_t k = 0; k < surface.size(); ++k) {
    const mesh::Tri& t = top[k % top.size()];
    c.def.surface_nodes.push_back(surface[k]);
    c.def.tri_nodes.push_back({t[0], t[1], t[2]});
    c.def.weights.push_back(weights[k % weights.size()]);
  }
  c.def.max_map_distance_m = 0.0;
  return owner;
}

// The same meshes with B standing on A's top: only B's bottom nodes (z = 0.04 m) are tied, each
// to its closest point of A's top face (a geometric map); B's sides and top are exposed.
inline std::unique_ptr<const TiedBox> make_bottom_tied_box() {
  auto owner = std::make_unique<TiedBox>();
  TiedBox& c = *owner;
  const auto all = make_tied_box();
  c.host = all->host;
  c.embedded = all->embedded;
  c.host_fixed = all->host_fixed;
  c.host_material = all->host_material;
  c.def = all->def;
  c.def.embedded = &c.embedded;
  c.def.surface_nodes.clear();
  c.def.tri_nodes.clear();
  c.def.weights.clear();
  std::vector<mesh::Tri> top;
  for (const auto& t : c.host.surface()) {
    bool on_top = true;
    for (int v : t) on_top = on_top && c.host.vertices()[v].z() > 0.04 - 1e-9;
    if (on_top) top.push_back(t);
  }
  for (int v : c.embedded.surface_vertices()) {
    const mesh::Vec3& x = c.embedded.vertices()[v];
    if (x.z() > 0.04 + 1e-9) continue;
    double best = 1e300;
    for (const auto& t : top) {
      const TrianglePoint p = closest_on_triangle(
          x, {c.host.vertices()[t[0]], c.host.vertices()[t[1]], c.host.vertices()[t[2]]});
      const double d = (p.point_m - x).norm();
      if (d >= best) continue;
      best = d;
      if (c.def.tri_nodes.size() > c.def.surface_nodes.size()) {
        c.def.tri_nodes.back() = {t[0], t[1], t[2]};
        c.def.weights.back() = p.weights;
      } else {
        c.def.tri_nodes.push_back({t[0], t[1], t[2]});
        c.def.weights.push_back(p.weights);
      }
    }
    c.def.surface_nodes.push_back(v);
    c.def.max_map_distance_m = std::max(c.def.max_map_distance_m, best);
  }
  return owner;
}

struct Monolithic {
  Eigen::VectorXd u_host_m;      // 3 N_A
  Eigen::VectorXd u_embedded_m;  // 3 N_B
};

// Direct solve of the monolithic tied system (KKT, the tie as Lagrange multipliers) for host
// nodal forces (3 N_A, unit N) and optionally forces on B's nodes.
class MonolithicSolver {
 public:
  explicit MonolithicSolver(const TiedBox& c) {
    na_ = static_cast<int>(c.host.num_vertices());
    nb_ = static_cast<int>(c.embedded.num_vertices());
    std::vector<char> fixed(na_, 0);
    for (int v : c.host_fixed) fixed[v] = 1;
    for (int d = 0; d < 3 * na_; ++d)
      if (!fixed[d / 3]) dof_.push_back(d);  // A's free dofs, then all of B's
    const int fa = static_cast<int>(dof_.size());
    for (int d = 0; d < 3 * nb_; ++d) dof_.push_back(3 * na_ + d);
    std::vector<int> index(3 * (na_ + nb_), -1);
    for (std::size_t r = 0; r < dof_.size(); ++r) index[dof_[r]] = static_cast<int>(r);
    const int n = static_cast<int>(dof_.size());
    const int nc = 3 * static_cast<int>(c.def.surface_nodes.size());
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(n + nc, n + nc);
    const Eigen::MatrixXd ka(
        fem::assemble_stiffness(c.host, fem::MaterialMap::uniform(c.host_material)));
    const Eigen::MatrixXd kb(
        fem::assemble_stiffness(c.embedded, fem::MaterialMap::uniform(c.def.material)));
    for (int r = 0; r < fa; ++r)
      for (int s = 0; s < fa; ++s) a(r, s) = ka(dof_[r], dof_[s]);
    a.block(fa, fa, 3 * nb_, 3 * nb_) = kb;
    for (std::size_t k = 0; k < c.def.surface_nodes.size(); ++k)
      for (int x = 0; x < 3; ++x) {
        const int row = n + 3 * static_cast<int>(k) + x;
        const int b = index[3 * na_ + 3 * c.def.surface_nodes[k] + x];
        a(row, b) += 1.0;
        for (int j = 0; j < 3; ++j) {
          const int h = index[3 * c.def.tri_nodes[k][j] + x];
          if (h >= 0) a(row, h) -= c.def.weights[k][j];
        }
      }
    // Scale the constraint rows to the stiffness (conditioning only: same solution).
    const double scale = ka.diagonal().maxCoeff();
    a.bottomRows(nc) *= scale;
    a.topRightCorner(n, nc) = a.bottomLeftCorner(nc, n).transpose();
    lu_.compute(a);
    size_ = n + nc;
  }

  // embedded_forces_n: B's nodal forces (3 N_B), or empty (none).
  Monolithic solve(const Eigen::VectorXd& host_forces_n,
                   const Eigen::VectorXd& embedded_forces_n = Eigen::VectorXd()) const {
    Eigen::VectorXd rhs = Eigen::VectorXd::Zero(size_);
    for (std::size_t r = 0; r < dof_.size(); ++r) {
      if (dof_[r] < 3 * na_)
        rhs[static_cast<int>(r)] = host_forces_n[dof_[r]];
      else if (embedded_forces_n.size() > 0)
        rhs[static_cast<int>(r)] = embedded_forces_n[dof_[r] - 3 * na_];
    }
    const Eigen::VectorXd x = lu_.solve(rhs);
    Monolithic m;
    m.u_host_m = Eigen::VectorXd::Zero(3 * na_);
    m.u_embedded_m = Eigen::VectorXd::Zero(3 * nb_);
    for (std::size_t r = 0; r < dof_.size(); ++r) {
      if (dof_[r] < 3 * na_)
        m.u_host_m[dof_[r]] = x[static_cast<int>(r)];
      else
        m.u_embedded_m[dof_[r] - 3 * na_] = x[static_cast<int>(r)];
    }
    return m;
  }

 private:
  int na_{0}, nb_{0}, size_{0};
  std::vector<int> dof_;  // unknown -> global dof (A: 0..3N_A-1, B: 3N_A + ...)
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
};

}  // namespace neurosim::interaction::tied_box
