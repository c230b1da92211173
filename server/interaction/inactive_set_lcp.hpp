// Solver of the contact LCP (lcp_problem.hpp) for a constant leading block of W (e.g. the
// sliding-coupling rows, n_s of them): the inverse G = W_ss^-1 is computed once (O(n_s^3), at
// load) and each solve works on the INACTIVE leading rows I (m of them) instead of the active
// ones: with lambda_I = 0 and the trailing (contact) rows c, active set A_c,
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
// n_s |A_c|) plus O(m^2) per flipped leading row, instead of O(k^2) per pivot for k active rows
// (active_set_lcp.hpp); an uncached coupling column costs O(n_s^2) once (cache of 16 x trailing
// capacity columns, LRU, keyed by a hash of the column and checked entry by entry, so a changed
// column is never taken from it). With column terms (LcpProblem::column_terms: a row's column as
// sum_t B_t c_t over fixed blocks, e.g. a contact row's nodes) the cache holds G B_t per block
// instead (max(32, 4 x trailing capacity) blocks of 3 columns, LRU, keyed by the term's key,
// address, offset and length): U_r = sum_t (G B_t) c_t costs O(n_s) per term, and a row whose
// weights change every step over the same nodes (a triangle row under a moving tool) no longer
// misses the cache; a new block costs O(n_s x its length) once. The result is checked as in the reference path: slack
// W_i lambda - delta_i of every inactive row from W itself, lambda_I = 0 to round-off (drift of
// the kept factor: past 1e3 x tolerance the solve is redone from a fresh factor, then reported
// as not converged). Memory: n_s^2 doubles for G, n_s^2 for L_I, 2 x 16 x trailing capacity x
// n_s for the column cache, 3 x max(32, 4 x trailing capacity) x n_s for the block cache. No allocation per solve once reserve() and set_constant_block() are done.
#pragma once

#include "server/interaction/lcp_problem.hpp"

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace neurosim::interaction {

class InactiveSetLcp {
 public:
  // Sizes the workspace for up to max_rows rows in all (allocates).
  void reserve(int max_rows);

  // Declares rows [0, rows) of w constant from now on (their W block; their delta may change,
  // at O(rows^2) per change): precomputes W_ss^-1 (allocates, O(rows^3)). false (and no
  // constant block) if the block is not numerically positive definite. rows == 0 clears it.
  bool set_constant_block(const Eigen::MatrixXd& w, int rows);
  int constant_rows() const { return ready_ ? constant_rows_ : 0; }
  // Rows after the constant block the workspace holds.
  int trailing_capacity() const { return trailing_cap_; }

  // The next solve starts from its warm start, not from the kept inactive set and factor.
  void forget_factor() { carry_ = false; }

  // Solves `problem` into lambda (first problem.rows entries; options.path is not used):
  // problem.stable_rows == constant_rows() > 0, at most trailing_capacity() rows after them,
  // inputs finite where ContactLcp::solve checks them. false: numerical trouble in the
  // inactive-set factor (the result is not usable; solve with the reference path instead).
  bool solve(const LcpProblem& problem, const LcpOptions& options, Eigen::VectorXd& lambda,
             LcpResult& result);

  // After a converged solve: the block of W_AA^-1 between the active rows >= first_row, which
  // must be >= constant_rows() (the trailing block is K^-1, O(|A_c|^3); the constant rows'
  // part of the inverse is not kept). Rows in the order of K's factor.
  void invert_active(int first_row, ActiveBlockInverse& out);

 private:
  int capacity_{0};
  bool ready_{false};
  int constant_rows_{0};      // n_s
  int trailing_cap_{0};       // trailing rows the workspace holds
  Eigen::MatrixXd g_;         // W_ss^-1
  Eigen::VectorXd ds_, a_;    // d_s of the last solve, a = G d_s
  bool carry_{false};         // inact_, li_ and the v column of zx_ carry over to the next solve
  int carried_solves_{0};
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
  // With column terms (LcpProblem::column_terms): cache of G B per block B (n_s x 3 each, LRU).
  Eigen::MatrixXd tg_;
  std::vector<std::uint64_t> tkey_;
  std::vector<const double*> tblock_;
  std::vector<int> toffset_, tlength_;
  std::vector<long long> tstamp_;  // last solve that used the entry (-1: empty)
  Eigen::MatrixXd ur_;  // U_r = G C_r per trailing row of this solve
  int nc_{0};           // trailing rows of this solve
  Eigen::MatrixXd h_;     // H = T - C^T U over the trailing rows
  Eigen::MatrixXd kl_;    // lower Cholesky factor of K over act_
  std::vector<int> act_;  // active trailing rows (factor order of K)
  int p_{0};
  Eigen::VectorXd e_, l_, xs_, wrow_, ys_, gs_, zrow_, rot_c_, rot_s_;
  std::vector<int> flips_;
  Eigen::MatrixXd columns_;  // workspace of invert_active: Lk^-1 e_a
  std::vector<int> wanted_;  // positions in act_ of the rows invert_active returns

  void size_workspace();
  // U_r of every trailing row into ur_: from the problem's column terms, or from the cache of
  // coupling columns.
  void trailing_columns(const LcpProblem& problem);
  // The cache entry of G B for a term's block (computed on a miss, O(n_s length)).
  int term_entry(const LcpColumnTerm& term);
  // Rebuilds li_ = chol(G_II) and v from inact_; false if G_II is not numerically definite.
  bool refactor_inactive();
  bool append_inactive(int row);  // false: G_II lost definiteness (round-off)
  void remove_inactive(int pos);
};

}  // namespace neurosim::interaction
