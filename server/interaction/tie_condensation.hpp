// One embedded mesh B tied to its host A, condensed onto its tied nodes (paper 2.3/2.6, Eq. 5-6).
//
// Every free surface node k of B is tied to a point of A's new boundary S' (a triangle of A,
// barycentric weights w): u_B,k = sum_a w_a u_A(node_a), or u_s = J u_A in matrix form (J:
// 3t x 3N_A, dimensionless). B's own fixed nodes stay fixed and are not tied. With B's tied
// nodes prescribed, its interior follows from K_ii (B with its tied and fixed nodes fixed:
// positive definite even when B has no fixed node), so B acts on A only through its Schur
// complement on the tied dofs
//
//   S_B = K_ss - K_si K_ii^-1 K_is   (unit N/m),
//
// and adds the stiffness K_add = J^T S_B J on A's boundary dofs. S_B itself is never formed
// (dense 3t x 3t): K_ss and K_is are kept sparse and S_B is only applied through J. This is the
// constant part of a tie (built once at load); the host's coupled compliance that uses it is
// CoupledBody's.
#pragma once

#include "server/fem/material.hpp"
#include "server/fem/static_solver.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

namespace neurosim::interaction {

// An embedded mesh B to tie to the host: B's surface nodes and, per node, the S' triangle of A it
// is tied to (A's node ids) with barycentric weights (the coupling map, paper 2.6).
struct TieDefinition {
  int mesh{-1};                            // index of B in the simulation
  const mesh::TetMesh* embedded{nullptr};  // must outlive the condensation
  fem::Material material;
  std::vector<int> fixed_nodes;                // B's own fixed nodes
  std::vector<int> surface_nodes;              // B's nodes to tie
  std::vector<std::array<int, 3>> tri_nodes;   // per surface node: A's node ids
  std::vector<std::array<double, 3>> weights;  // per surface node, dimensionless, sum 1
  double max_map_distance_m{0.0};              // largest node-to-S' distance of the map, unit m
};

class TieCondensation {
 public:
  // Checks the map against a host of host_vertices nodes (sizes, B's and A's node ids, finite
  // weights summing to 1; at least one node to tie), drops B's fixed nodes from it, factors
  // K_ii and extracts K_ss and K_is. Throws std::invalid_argument for a bad map (naming B's
  // node) and what fem::StaticSolver throws for a bad mesh or material.
  TieCondensation(const TieDefinition& def, int host_vertices);

  int mesh() const { return mesh_; }  // index of B in the simulation
  const mesh::TetMesh& geometry() const { return *geometry_; }
  const fem::Material& material() const { return material_; }
  const std::vector<int>& fixed_nodes() const { return fixed_nodes_; }  // B's, sorted
  // B's tied nodes (the definition's surface nodes without the fixed ones, in its order) and
  // per tied node A's three node ids and their weights.
  const std::vector<int>& tied_nodes() const { return tied_nodes_; }
  const std::vector<std::array<int, 3>>& host_nodes() const { return host_nodes_; }
  const std::vector<std::array<double, 3>>& weights() const { return weights_; }
  double max_map_distance_m() const { return max_map_distance_m_; }

  // k_add += J^T S_B J (unit N/m) on A's boundary dofs: boundary_slot maps an A node to its
  // slot s (dofs 3s..3s+2 of k_add, a 3m x 3m matrix) and must give one to every host node of
  // the map. One solve of K_ii with 3m right-hand sides.
  void add_stiffness(const std::vector<int>& boundary_slot, Eigen::MatrixXd& k_add) const;

  // u_s = J u_A: the tied nodes' displacement (3t, node-major) for A's (3N_A), unit m.
  void tied_displacement(const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_tied_m) const;
  // B's displacement (3N_B) for A's (3N_A), unit m: tied nodes u_s = J u_A, interior from K_ii,
  // fixed nodes zero. The tie holds to round-off by construction. ws: the caller's solve scratch
  // (a State, a field worker); null uses K_ii's own, locked workspace (set-up, offline).
  void displacement(const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m,
                    fem::SolveWorkspace* ws = nullptr) const;
  // Forces on B's own nodes (3N_B, unit N; those on B's fixed nodes are reactions, ignored):
  // with z = K_ii^-1 f_i (B's interior, its tied nodes held), the equivalent load the tie puts on
  // A, host_load_n += J^T (f_s - K_si z) (3N_A, unit N). With it A's coupled displacement is the
  // tied system's (the load on an exposed, untied node of B reaches A through B's interior).
  void add_equivalent_host_load(const Eigen::VectorXd& forces_n,
                                Eigen::VectorXd& host_load_n) const;
  // B's displacement (3N_B) for A's and the forces on B's nodes (3N_B, unit N): tied nodes
  // J u_A, the others from K_ii with the forces (one solve_prescribed), fixed nodes zero.
  // ws as for displacement above.
  void displacement(const Eigen::VectorXd& u_host_m, const Eigen::VectorXd& forces_n,
                    Eigen::VectorXd& u_m, fem::SolveWorkspace* ws = nullptr) const;
  // Block forms for k load cases at once (one solve of K_ii with k right-hand sides each), as
  // the tool's contact columns on an exposed B need them: host_load_n (3N_A x k) +=
  // J^T (F_s - K_si K_ii^-1 F_i) for forces_n (3N_B x k); and u_m (3N_B x k) = B's displacement
  // for A's u_host_m (3N_A x k) and the forces on B (3N_B x k, or 0 columns: none).
  void add_equivalent_host_loads(const Eigen::MatrixXd& forces_n, Eigen::MatrixXd& host_load_n,
                                 fem::SolveWorkspace* ws = nullptr) const;
  void displacements(const Eigen::MatrixXd& u_host_m, const Eigen::MatrixXd& forces_n,
                     Eigen::MatrixXd& u_m, fem::SolveWorkspace* ws = nullptr) const;
  // Solves of K_ii on its own (locked) workspace since construction.
  std::uint64_t shared_workspace_uses() const {
    return interior_ ? interior_->shared_workspace_uses() : 0;
  }
  // max_k |sum_a w_a u_A(node_a) - u_B,k| over the tied nodes, unit m.
  double residual(const Eigen::VectorXd& u_host_m, const Eigen::VectorXd& u_embedded_m) const;

 private:
  int mesh_{-1};
  const mesh::TetMesh* geometry_{nullptr};
  fem::Material material_;
  std::vector<int> fixed_nodes_;
  std::vector<int> tied_nodes_;
  std::vector<std::array<int, 3>> host_nodes_;
  std::vector<std::array<double, 3>> weights_;
  double max_map_distance_m_{0.0};
  std::unique_ptr<fem::StaticSolver> interior_;  // K_ii: B, tied + fixed nodes fixed (null: none)
  // K_B blocks (unit N/m): tied x tied, and interior free (reduced index of interior_) x tied.
  Eigen::SparseMatrix<double> k_ss_;
  Eigen::SparseMatrix<double> k_is_;
};

}  // namespace neurosim::interaction
