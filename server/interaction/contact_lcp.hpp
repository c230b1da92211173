// Small dense LCP of the unilateral tool contact: find lambda >= 0 with
//   w = W lambda - delta >= 0,  lambda . w = 0
// (W: effective contact compliance on the candidate rows, unit m/N, symmetric positive
// definite; delta: penetration depth per row, unit m; lambda: normal force per row, unit N).
// Solved exactly by principal pivoting (Murty's least-index rule, finite for P-matrices) with a
// Cholesky factor of the active block, updated per pivot (a row added: one forward solve; a row
// removed: Givens rotations), O(k^2) per pivot for k active rows, and kept from one solve to the
// next for rows the caller declares unchanged; no allocation once reserve() has sized the
// workspace.
//
// Constant leading block (set_constant_block, e.g. the sliding-coupling rows, n_s of them): the
// inverse G = W_ss^-1 is computed once (O(n_s^3), at load) and each solve works on the INACTIVE
// leading rows I (m of them) instead of the active ones: with lambda_I = 0 and the trailing
// (contact) rows c, active set A_c,
//   G_II w_I = U_Ic l - a_I                      (w_I: slack of the inactive rows, unit m)
//   (H + Z^T Z)_AcAc l = d_Ac - C_Ac^T a + Z^T v (l: trailing forces, unit N)
//   lambda_s = a - U l + G_:I w_I
// with a = G d_s, U = G C (C: coupling columns W_sc; cached per distinct column), H = T - C^T U
// (T = W_cc), L_I L_I^T = G_II, Z = L_I^-1 U_I, v = L_I^-1 a_I. K = H + Z^T Z is the Schur
// complement of the trailing rows, i.e. the trailing block of the inverse of the active block
// (the contact stiffness). L_I is kept between solves and updated per pivot (O(m^2): a row leaves
// I by Givens rotations, applied to Z too; a row joins I by one forward solve); K (<= ~20 rows) is
// refactored per iteration. Pivoting: block principal pivoting (Judice-Pires: every infeasible
// index flips while their number falls, three more tries otherwise), then Murty's least-index
// rule (finite for P-matrices) until the end of that solve. Cost per iteration O(m^2 + n_s m +
// n_s |A_c|) plus O(m^2) per flipped leading row, instead of O(k^2) per pivot for k active rows;
// an uncached coupling column costs O(n_s^2) once (cache of 16 x trailing capacity columns, LRU,
// keyed by a hash of the column and checked entry by entry, so a changed column is never taken
// from it). The result is checked as in the reference path: slack W_i lambda - delta_i of every
// inactive row from W itself, lambda_I = 0 to round-off (drift of the kept factor: past
// 1e3 x tolerance the solve is redone from a fresh factor, then reported as not converged).
// Both paths solve the same LCP (unique solution, W SPD); the factor goes to the smaller set:
// this path when more than 60 % of the leading rows start active, the reference path below
// 40 % (hysteresis; a switch refactors from the warm start once, O(rows^3)). Memory: n_s^2
// doubles for G, n_s^2 for L_I, 2 x 16 x trailing capacity x n_s for the cache.
#pragma once

#include <Eigen/Core>

#include <vector>

namespace neurosim::interaction {

struct LcpResult {
  bool converged{false};
  int iterations{0};           // pivots (each one Cholesky of the active block); inactive-set path:
                               // block-pivoting passes (each flips one or more rows)
  int active{0};               // rows with lambda > 0
  double max_violation{0.0};   // max(-w, -lambda, 0) relative to max |delta|
  bool dependent_rows{false};  // a row of the active block was (numerically) dependent
};

class ContactLcp {
 public:
  // Sizes the workspace for up to max_rows rows (allocates).
  void reserve(int max_rows);
  int capacity() const { return capacity_; }

  // Declares rows [0, rows) of w constant from now on (their W block and its use as stable_rows;
  // their delta may change, at O(rows^2) per change): precomputes W_ss^-1 (allocates,
  // O(rows^3)). Solves with stable_rows == rows then take the inactive-set path described
  // above; false (and the active-factor path stays in use) if the block is not numerically
  // positive definite. rows == 0 clears it.
  bool set_constant_block(const Eigen::MatrixXd& w, int rows);
  int constant_rows() const { return schur_ready_ ? schur_rows_ : 0; }
  // Selects the path for the constant block: true (default) the inactive-set path, false the
  // active-factor reference path (both solve the same LCP to the same tolerance).
  // With it on, each solve takes the inactive-set path when most leading rows start active and
  // the reference path when few do (the factor goes to the smaller set; see solve()); always:
  // the inactive-set path whatever the warm start (tests).
  void use_inactive_set(bool on, bool always = false) {
    use_schur_ = on;
    always_schur_ = always;
  }
  // The last solve took the inactive-set path.
  bool last_solve_inactive_set() const { return last_schur_; }

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
  // After an inactive-set solve, first_row must be >= constant_rows() (the inverse's trailing
  // block is K^-1, O(|A_c|^3)).
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

  // Inactive-set path (see the top of the file).
  bool schur_ready_{false};
  bool use_schur_{true};
  bool always_schur_{false};
  bool last_schur_{false};    // the last solve took the inactive-set path
  bool prefer_schur_{false};  // path for the constant block (hysteresis on the warm start)
  int schur_rows_{0};         // n_s
  int contact_cap_{0};        // trailing rows the workspace holds
  Eigen::MatrixXd g_;         // W_ss^-1
  Eigen::VectorXd ds_, a_;    // d_s of the last solve, a = G d_s
  bool schur_carry_{false};   // inact_, li_ and the v column of zx_ carry over to the next solve
  int schur_solves_{0};
  std::vector<char> status_;  // per row: 0 inactive, 1 active, 2 blocked
  std::vector<int> inact_;    // I in factor order
  int m_{0};
  Eigen::MatrixXd li_;  // lower Cholesky factor of G_II (top-left m x m)
  Eigen::MatrixXd zx_;  // column 0: v, column 1 + r: Z for trailing row r (top m rows)
  Eigen::MatrixXd cc_;  // cache of coupling columns C_r ...
  Eigen::MatrixXd uc_;  // ... and U_r = G C_r
  std::vector<unsigned long long> chash_;
  std::vector<long long> cstamp_;  // last solve that used the entry (-1: empty)
  long long solve_count_{0};
  std::vector<int> centry_;  // per trailing row: its cache entry
  std::vector<int> miss_;
  Eigen::MatrixXd h_;     // H = T - C^T U over the trailing rows
  Eigen::MatrixXd kl_;    // lower Cholesky factor of K over act_
  std::vector<int> act_;  // active trailing rows (factor order of K)
  int p_{0};
  Eigen::VectorXd e_, l_, xs_, wrow_, ys_, gs_, zrow_, rot_c_, rot_s_;
  std::vector<int> flips_;

  void size_schur_workspace();
  // Rebuilds li_ = chol(G_II) and v from inact_; false if G_II is not numerically definite.
  bool refactor_inactive();
  bool append_inactive(int row);  // false: G_II lost definiteness (round-off)
  void remove_inactive(int pos);
  // delta_scale: max |delta| over the n rows (solve() has it from its input checks).
  bool solve_schur(const Eigen::MatrixXd& w, const Eigen::VectorXd& delta, int n,
                   double delta_scale, double tolerance, int max_iterations,
                   Eigen::VectorXd& lambda, const std::vector<char>* initial_active,
                   LcpResult& result);
};

}  // namespace neurosim::interaction
