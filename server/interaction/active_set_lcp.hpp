// Reference solver of the contact LCP (lcp_problem.hpp): principal pivoting (Murty's
// least-index rule, finite for P-matrices) with a Cholesky factor of the active block, updated
// per pivot (a row added: one forward solve; a row removed: Givens rotations), O(k^2) per pivot
// for k active rows, and kept from one solve to the next for the rows the problem declares
// stable (refactored from scratch every 1000 solves, so round-off of the updates cannot pile
// up). No allocation once reserve() has sized the workspace.
// The canonical answer (problems without stable rows): the pivoting only decides which rows are
// active; lambda (and the factor invert_active reads) is then computed once more from scratch
// from that set alone, its rows factored in index order, and checked for complementarity. So
// the answer is a function of W, delta and the active set, whatever the pivots' order: a warm
// start from history (LcpProblem::warm_active) gives the cold start's bits whenever the two end
// with the same set, which they do for a nondegenerate solution (unique set, W SPD). The warm
// set is taken only if its answer is complementary with a margin (LcpOptions::warm_margin, no
// dependent row); otherwise, as when the set's own answer misses the tolerance at its edge, the
// cold start decides (and at that edge its pivots' own answer stands).
#pragma once

#include "server/interaction/lcp_problem.hpp"

#include <Eigen/Core>

#include <vector>

namespace neurosim::interaction {

class ActiveSetLcp {
 public:
  // Sizes the workspace for up to max_rows rows (allocates).
  void reserve(int max_rows);
  int capacity() const { return capacity_; }

  // Solves `problem` into lambda (first problem.rows entries; options.path is not used). The
  // inputs must fit the workspace and be finite where ContactLcp::solve checks them. Rows of W
  // with a zero diagonal (a row that cannot move) never become active. The result is checked
  // from W itself: slack of every row, sign of every force (max_violation); past 1e3 x
  // tolerance, or with a non-finite lambda, it is reported as not converged.
  LcpResult solve(const LcpProblem& problem, const LcpOptions& options, Eigen::VectorXd& lambda);

  // The next solve starts from its warm start, not from the kept factor (e.g. after another
  // solver took the steps in between).
  void forget_factor() { factor_valid_ = false; }

  // After a converged solve: the block of W_AA^-1 between the active rows >= first_row, in the
  // order of the factor (out sized by its reserve(capacity())). (W_AA^-1)(c, d) = z_c . z_d with
  // z_c = L^-1 e_c, zero above position c: the rows appended last (e.g. the contact rows, after
  // the kept sliding rows) cost only the factor's tail.
  void invert_active(int first_row, ActiveBlockInverse& out);

 private:
  int capacity_{0};
  std::vector<char> in_set_;  // per row: 0 inactive, 1 active, 2 blocked (never active)
  std::vector<int> active_rows_;
  int num_active_{0};
  Eigen::MatrixXd chol_;       // lower Cholesky factor of the active block
  Eigen::MatrixXd columns_;    // workspace of invert_active: L^-1 e_c per wanted column
  std::vector<int> position_;  // their positions
  Eigen::VectorXd rhs_, sol_, z_, w_;

  bool factor_valid_{false};  // chol_ factors the block of active_rows_ of the last solve's W
  int factored_rows_{0};      // rows of that solve
  int solves_since_factor_{0};

  // Murty's pivoting from start_active (nullptr: the rows with delta > 0) into in_set_, the
  // factor and lambda; the result's converged, iterations and dependent_rows.
  LcpResult pivot(const LcpProblem& problem, const LcpOptions& options,
                  const std::vector<char>* start_active, double delta_scale,
                  Eigen::VectorXd& lambda);
  // The canonical answer of the active set in_set_: its factor from scratch in row order
  // (refactor false: the pivoting's first factor, which is that), lambda from it, and whether
  // it is complementary: within the tolerance (margin < 0) or by margin x the scales.
  bool settle(const LcpProblem& problem, const LcpOptions& options, double delta_scale,
              double margin, bool refactor, Eigen::VectorXd& lambda);
  // The result's active count and max_violation, from W itself.
  void finish(const LcpProblem& problem, const LcpOptions& options, double delta_scale,
              Eigen::VectorXd& lambda, LcpResult& result);
  // Appends `row` to the active block and its factor (one forward solve); false (nothing
  // changed) if the row is numerically dependent on the active ones.
  bool append_row(const Eigen::MatrixXd& w, int row);
  // Removes the active row at position p of active_rows_ (Givens rotations restore the factor).
  void remove_position(int p);
  // z_ = L^-1 delta_A from position `from` on (the part above is still valid).
  void forward_from(const Eigen::VectorXd& delta, int from);
  // sol_ (factor order) = L^-T z_ = W_AA^-1 delta_A.
  void back_solve();
};

}  // namespace neurosim::interaction
