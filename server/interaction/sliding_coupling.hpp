// Frictionless sliding contact between a host mesh A (through its new boundary S') and an
// embedded mesh B that is not bonded to it (coupling kind SLIDING): the meshes may
// separate but not interpenetrate.
//
// One unilateral normal row per surface node k of B, paired with its closest point on S'
// (triangle of A, barycentric weights w, from the coupling map):
//
//   g_k = n_k . (sum_a w_a u_A,a - u_B,k) + g0_k  >= 0,   lambda_k >= 0,   lambda_k g_k = 0
//
// n_k: B's outward unit surface normal at k (from B towards A); g0_k >= 0: initial normal gap
// (0 when the meshes touch at rest). g_k < 0 is interpenetration. lambda_k (unit N) pushes the
// meshes apart: +lambda_k n_k on A's S' point (spread by w), -lambda_k n_k on B's node k. No
// tangential row: the meshes slide freely along each other.
// In constraint form: J_A row k = n_k^T (x) w on A's dofs, J_B row k = -n_k^T at B's node k, and
// the Delassus block of the rows is W_ss = J_A L_A J_A^T + J_B L_B J_B^T. The host part is
// SlidingOperator::compliance() (sliding_operator.hpp); this file holds B's part and B's
// displacement.
//
// B with fixed nodes: L_B = K_B^-1 with those nodes fixed. A floating B (no fixed node) has six
// rigid modes R that frictionless contact alone may not hold (a cylinder turning about its
// axis); it is anchored in those modes only: L_B = K_B^+ + R R^T / kappa with
// kappa = anchor_ratio x mean diagonal of K_B (deformation modes exact: the pseudo-inverse is one
// solve on a statically determinate six-dof support followed by the projection out of R; a rigid
// load moves B by load / kappa).
#pragma once

#include "server/fem/material.hpp"
#include "server/fem/static_solver.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::fem {
class StaticSolver;
}

namespace neurosim::interaction {

struct SlidingPair {
  int embedded_node{-1};                            // B's node id
  std::array<int, 3> host_nodes{};                  // A's triangle of S'
  std::array<double, 3> weights{};                  // barycentric weights on it
  Eigen::Vector3d normal{Eigen::Vector3d::Zero()};  // unit, B's outward normal at the node
  double initial_gap_m{0.0};                        // g0 >= 0, unit m
};

// Compliance operator of an embedded mesh (see above).
class EmbeddedCompliance {
 public:
  // what: names the mesh in messages. anchor_ratio > 0 (dimensionless) is used when fixed is
  // empty.
  EmbeddedCompliance(const mesh::TetMesh& mesh, const fem::Material& material,
                     const std::vector<int>& fixed, double anchor_ratio, const std::string& what);
  ~EmbeddedCompliance();
  EmbeddedCompliance(const EmbeddedCompliance&) = delete;
  EmbeddedCompliance& operator=(const EmbeddedCompliance&) = delete;

  // U = L_B F for nodal forces F (3N x m, unit N), U unit m.
  // ws: the caller's solve scratch; null uses B's own, locked workspace (set-up, offline).
  void apply(const Eigen::MatrixXd& forces_n, Eigen::MatrixXd& u_m,
             fem::SolveWorkspace* ws = nullptr) const;
  bool floating() const { return !solver_; }
  // Solves on B's own (locked) workspace since construction.
  std::uint64_t shared_workspace_uses() const { return solver_ ? solver_->shared_workspace_uses() : 0; }

 private:
  struct Floating;
  std::unique_ptr<fem::StaticSolver> solver_;  // B with fixed nodes
  std::unique_ptr<Floating> floating_;         // B without
  std::string what_;
  int dofs_{0};
};

// The embedded mesh B of a sliding coupling and its pairs.
struct SlidingDefinition {
  int mesh{-1};  // index of B in the simulation
  const mesh::TetMesh* embedded{nullptr};  // must outlive the coupling
  fem::Material material;
  std::vector<int> fixed_nodes;     // B's own fixed nodes
  std::vector<SlidingPair> pairs;   // one per free surface node of B
  double anchor_ratio{1e-6};        // a floating B: rigid-mode anchor / mean diagonal stiffness
  std::string what;                 // names the coupling in messages
};

class SlidingCoupling {
 public:
  // Pairs checked: finite, unit normals, g0 >= 0. Throws std::invalid_argument naming `what`.
  explicit SlidingCoupling(SlidingDefinition def);

  int mesh() const { return mesh_; }
  const mesh::TetMesh& geometry() const { return *geometry_; }
  const std::vector<SlidingPair>& pairs() const { return pairs_; }
  const fem::Material& material() const { return material_; }
  const std::vector<int>& fixed_nodes() const { return fixed_; }  // B's own, sorted
  int size() const { return static_cast<int>(pairs_.size()); }
  // W_B = J_B L_B J_B^T (pairs x pairs), unit m/N.
  const Eigen::MatrixXd& compliance() const { return w_b_; }
  const EmbeddedCompliance& operator_b() const { return *compliance_; }
  // B's displacement (3N_B, unit m) for the row forces lambda (pairs, unit N); ws as in
  // EmbeddedCompliance::apply.
  void displacement(const Eigen::VectorXd& lambda_n, Eigen::VectorXd& u_m,
                    fem::SolveWorkspace* ws = nullptr) const;
  // The same with other forces on B's nodes too (3N_B, unit N: a tool's on B's exposed part).
  void displacement(const Eigen::VectorXd& lambda_n, const Eigen::VectorXd& forces_b_n,
                    Eigen::VectorXd& u_m, fem::SolveWorkspace* ws = nullptr) const;
  std::uint64_t shared_workspace_uses() const { return compliance_->shared_workspace_uses(); }
  // g_k for the given full fields of A and B (unit m).
  double gap(int k, const Eigen::VectorXd& u_host_m, const Eigen::VectorXd& u_embedded_m) const;

 private:
  int mesh_{-1};
  const mesh::TetMesh* geometry_{nullptr};
  std::vector<SlidingPair> pairs_;
  fem::Material material_;
  std::vector<int> fixed_;
  std::unique_ptr<EmbeddedCompliance> compliance_;
  Eigen::MatrixXd w_b_;
};

}  // namespace neurosim::interaction
