// Small dense LCP of the unilateral tool contact: find lambda >= 0 with
//   w = W lambda - delta >= 0,  lambda . w = 0
// (W: effective contact compliance on the candidate rows, unit m/N, symmetric positive
// definite; delta: penetration depth per row, unit m; lambda: normal force per row, unit N).
// Solved exactly by principal pivoting (Murty's least-index rule, finite for P-matrices) with a
// Cholesky factor of the active block, updated per pivot (a row added: one forward solve; a row
// removed: Givens rotations), O(k^2) per pivot for k active rows, and kept from one solve to the
// next for rows the caller declares unchanged; no allocation once reserve() has sized the
// workspace.
#pragma once

#include <Eigen/Core>

#include <vector>

namespace neurosim::interaction {

struct LcpResult {
  bool converged{false};
  int iterations{0};           // pivots (each one Cholesky of the active block)
  int active{0};               // rows with lambda > 0
  double max_violation{0.0};   // max(-w, -lambda, 0) relative to max |delta|
  bool dependent_rows{false};  // a row of the active block was (numerically) dependent
};

class ContactLcp {
 public:
  // Sizes the workspace for up to max_rows rows (allocates).
  void reserve(int max_rows);
  int capacity() const { return capacity_; }

  // w: top-left n x n block of a capacity x capacity matrix is used; delta, lambda: first n.
  // tolerance: relative to max |delta| (for w) and max lambda (for lambda).
  // Rows of W with a zero diagonal (a row that cannot move) never become active.
  // initial_active (optional, first n entries): warm start from this active set (e.g. the last
  // step's) instead of the rows with delta > 0; the pivoting is finite from any start.
  // stable_rows: rows [0, stable_rows) have the same entries of W as in the previous solve (e.g.
  // the constant block of sliding-coupling rows): their active set and its factor are taken
  // over from the previous solve (initial_active then applies to the other rows only).
  LcpResult solve(const Eigen::MatrixXd& w, const Eigen::VectorXd& delta, int n, double tolerance,
                  int max_iterations, Eigen::VectorXd& lambda,
                  const std::vector<char>* initial_active = nullptr, int stable_rows = 0);

  // After a converged solve: the inverse of the active block (for the contact stiffness), in
  // active_inverse() (top-left active x active), rows listed by active_rows(). Only the entries
  // between active rows >= first_row are computed (e.g. the contact rows after the sliding rows).
  void invert_active(int first_row = 0);
  const Eigen::MatrixXd& active_inverse() const { return inverse_; }
  const std::vector<int>& active_rows() const { return active_rows_; }
  int num_active() const { return num_active_; }

 private:
  int capacity_{0};
  std::vector<char> in_set_;
  std::vector<int> active_rows_;
  int num_active_{0};
  Eigen::MatrixXd chol_;       // lower Cholesky factor of the active block
  Eigen::MatrixXd inverse_;    // inverse of the active block
  Eigen::MatrixXd columns_;    // workspace of invert_active: L^-1 e_c per wanted column
  std::vector<int> position_;  // their positions
  Eigen::VectorXd rhs_, sol_, z_, w_;

  bool factor_valid_{false};  // chol_ factors the block of active_rows_ of the last solve's W
  int factored_rows_{0};      // n of that solve
  int solves_since_factor_{0};

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
