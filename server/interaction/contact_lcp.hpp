// ContactLcp: the contact LCP of one simulation step (lcp_problem.hpp: find lambda >= 0 with
// w = W lambda - delta >= 0, lambda . w = 0; W compliance, unit m/N, SPD; delta depth, unit m;
// lambda force, unit N) and the contact stiffness it implies. A front over two solvers of the
// same LCP (unique solution, W SPD), which reach the same tolerance:
//   - the reference path (active_set_lcp.hpp): principal pivoting with a Cholesky factor of the
//     active block, kept between solves for the stable rows;
//   - the inactive-set path (inactive_set_lcp.hpp), once set_constant_block() declared a
//     constant leading block: W_ss^-1 precomputed, a factor of the inactive leading rows.
// The factor goes to the smaller set: for a problem whose stable rows are the constant block,
// the inactive-set path when more than 60 % of the leading rows start active, the reference path
// below 40 % (hysteresis; a switch refactors from the warm start once, O(rows^3)); numerical
// trouble in the inactive-set factor falls back to the reference path. The front checks the
// inputs (sizes, finite depths and diagonal); each path checks its result from W itself
// (LcpResult::max_violation; past 1e3 x tolerance: not converged). No allocation per solve or
// per stiffness once reserve() (and set_constant_block()) are done.
#pragma once

#include "server/interaction/active_set_lcp.hpp"
#include "server/interaction/inactive_set_lcp.hpp"
#include "server/interaction/lcp_problem.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::interaction {

class ContactLcp {
 public:
  // Sizes the workspace for up to max_rows rows (allocates).
  void reserve(int max_rows);
  int capacity() const { return capacity_; }

  // Declares rows [0, rows) of W constant from now on (their W block; their delta may change, at
  // O(rows^2) per change): precomputes W_ss^-1 (allocates, O(rows^3)). Problems with
  // stable_rows == rows may then take the inactive-set path (LcpOptions::path); false (and the
  // reference path stays in use) if the block is not numerically positive definite. rows == 0
  // clears it.
  bool set_constant_block(const Eigen::MatrixXd& w, int rows);
  int constant_rows() const { return inactive_set_.constant_rows(); }

  // Solves `problem` into lambda (first problem.rows entries, unit N). Throws
  // std::invalid_argument if the problem exceeds the workspace or its inputs, or if a depth or a
  // diagonal entry of W is not finite; running out of iterations is reported (converged false).
  LcpResult solve(const LcpProblem& problem, const LcpOptions& options, Eigen::VectorXd& lambda);
  // The last solve took the inactive-set path.
  bool last_solve_inactive_set() const { return last_inactive_set_; }

  // After a converged solve: the contact stiffness of one group of rows (e.g. one tool's contact
  // rows), unit N/m,
  //   dF/dx = -sum_{j,k} (W_AA^-1)_jk n_j n_k^T
  // over the active rows j, k >= first_row of the group: direction(row) (called with LCP rows
  // >= first_row) returns a pointer to the row's unit direction n (Eigen::Vector3d; the contact
  // normal: the depth changes by -n.dx), or nullptr if the row is not in the group. W_AA^-1 is
  // the inverse of the whole active block (active rows before first_row, e.g. sliding rows,
  // stay active). Its block between the active rows >= first_row is computed once per solve
  // (the first call), so the groups of one solve share it. After an inactive-set solve,
  // first_row must be >= constant_rows() (std::logic_error otherwise, or without a converged
  // solve).
  template <class Direction>
  Eigen::Matrix3d contact_stiffness(int first_row, const Direction& direction);
  // The same between two groups: -sum_{j in left, k in right} (W_AA^-1)_jk n_j n_k^T (the
  // left group's force per unit force pushed along the right group's rows: contact_step.cpp
  // near_field_tangent, one part's near field).
  template <class Left, class Right>
  Eigen::Matrix3d contact_stiffness(int first_row, const Left& left, const Right& right);

 private:
  int capacity_{0};
  ActiveSetLcp reference_;
  InactiveSetLcp inactive_set_;
  bool last_inactive_set_{false};  // the last solve took the inactive-set path
  bool prefer_inactive_set_{false};  // path for the constant block (hysteresis on the warm start)
  bool converged_{false};            // the last solve converged
  ActiveBlockInverse inverse_;       // block of W_AA^-1 between the active rows >= ...
  int inverse_first_row_{-1};        // ... this row (-1: not computed for the last solve)
  std::vector<int> group_;           // contact_stiffness: positions in inverse_ of the group
  std::vector<const Eigen::Vector3d*> directions_;  // and their directions

  // inverse_ for first_row, computed once per solve.
  const ActiveBlockInverse& active_inverse(int first_row);
};

template <class Direction>
Eigen::Matrix3d ContactLcp::contact_stiffness(int first_row, const Direction& direction) {
  const ActiveBlockInverse& inv = active_inverse(first_row);
  int m = 0;
  for (int a = 0; a < inv.count; ++a) {
    const Eigen::Vector3d* n = direction(inv.rows[a]);
    if (n == nullptr) continue;
    group_[m] = a;
    directions_[m++] = n;
  }
  Eigen::Matrix3d stiffness = Eigen::Matrix3d::Zero();
  for (int j = 0; j < m; ++j)
    for (int k = 0; k < m; ++k)
      stiffness.noalias() -= inv.inverse(group_[j], group_[k]) * *directions_[j] *
                             directions_[k]->transpose();
  return stiffness;
}

template <class Left, class Right>
Eigen::Matrix3d ContactLcp::contact_stiffness(int first_row, const Left& left,
                                              const Right& right) {
  const ActiveBlockInverse& inv = active_inverse(first_row);
  int m = 0;
  for (int a = 0; a < inv.count; ++a) {
    const Eigen::Vector3d* n = left(inv.rows[a]);
    if (n == nullptr) continue;
    group_[m] = a;
    directions_[m++] = n;
  }
  Eigen::Matrix3d stiffness = Eigen::Matrix3d::Zero();
  for (int a = 0; a < inv.count; ++a) {
    const Eigen::Vector3d* nk = right(inv.rows[a]);
    if (nk == nullptr) continue;
    Eigen::Vector3d column = Eigen::Vector3d::Zero();  // sum_j (W_AA^-1)_ja n_j
    for (int j = 0; j < m; ++j) column += inv.inverse(group_[j], a) * *directions_[j];
    stiffness.noalias() -= column * nk->transpose();
  }
  return stiffness;
}

}  // namespace neurosim::interaction
