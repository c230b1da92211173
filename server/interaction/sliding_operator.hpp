// Host side of the sliding couplings of a body (coupling kind SLIDING, sliding_coupling.hpp).
//
// Row k of a sliding coupling measures the normal motion of a point of A's new boundary S':
// n_k . sum_a w_a u_A(node_a) (a triangle of A, barycentric weights w, B's unit normal n). On A's
// free dofs the rows form J_A (rows x free dofs, dimensionless; fixed dofs do not move), and
// their host part of the Delassus matrix is W_A = J_A L J_A^T (unit m/N) with L the body's
// coupled compliance (ties included). Both are constant: built once at load, W_A by block
// solves with the rows' force patterns as right-hand sides. A contact column L[:, slot] adds
// the rows J_A L[:, slot] (apply), its coupling with the sliding rows.
#pragma once

#include "server/fem/static_solver.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <array>
#include <functional>
#include <string>
#include <vector>

namespace neurosim::interaction {

// Host side of one row of a sliding coupling: the row measures n . sum_a w_a u_A(node_a).
struct HostSlidingRow {
  std::array<int, 3> nodes{};                       // A's node ids (a triangle of S')
  std::array<double, 3> weights{};                  // barycentric, dimensionless: >= 0, sum 1
  Eigen::Vector3d normal{Eigen::Vector3d::Zero()};  // unit
};

// Throws std::invalid_argument naming `what` and the row (its index in `rows`) for a node out
// of [0, host_vertices), a negative or non-finite weight, weights not summing to 1, a normal
// that is not finite or not unit (zero included).
void check_sliding_rows(const std::vector<HostSlidingRow>& rows, int host_vertices,
                        const std::string& what);

// X = L B on A's free dofs (B: free dofs x k right-hand sides, unit N; X unit m), with L the
// body's coupled compliance.
using FreeDofSolve = std::function<void(const Eigen::MatrixXd& b, Eigen::MatrixXd& x)>;

// What a sliding operator is built from.
struct SlidingOperatorDefinition {
  std::vector<HostSlidingRow> rows;        // every sliding row of the host, stacked
  const fem::StaticSolver* host{nullptr};  // A's factor: node count, free-dof numbering
  FreeDofSolve coupled_solve;              // L on A's free dofs (used only while building)
  int block_columns{0};                    // right-hand sides per coupled_solve call, > 0
};

class SlidingOperator {
 public:
  SlidingOperator() = default;  // no rows
  // Checks the rows (check_sliding_rows), builds J_A and W_A. Throws std::invalid_argument for
  // a bad row or definition, std::runtime_error if W_A is not finite.
  explicit SlidingOperator(SlidingOperatorDefinition def);

  int size() const { return static_cast<int>(rows_.size()); }
  const std::vector<HostSlidingRow>& rows() const { return rows_; }
  // J_A on A's free dofs (rows x free dofs, the reduced index of the host's StaticSolver).
  const Eigen::SparseMatrix<double, Eigen::RowMajor>& jacobian() const { return j_; }
  // W_A = J_A L J_A^T (rows x rows, symmetric), unit m/N.
  const Eigen::MatrixXd& compliance() const { return w_; }
  // J_A X for free-dof columns X (free dofs x k), e.g. J_A L[:, slot] of a contact column
  // (rows x 3, unit m/N for X in m/N).
  Eigen::MatrixXd apply(const Eigen::Ref<const Eigen::MatrixXd>& x) const;

 private:
  std::vector<HostSlidingRow> rows_;
  Eigen::SparseMatrix<double, Eigen::RowMajor> j_;
  Eigen::MatrixXd w_;
};

}  // namespace neurosim::interaction
