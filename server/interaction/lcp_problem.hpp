// The small dense LCP of the unilateral tool contact (and the sliding rows solved with it):
// find lambda >= 0 with
//   w = W lambda - delta >= 0,  lambda . w = 0
// (W: effective contact compliance on the candidate rows, unit m/N, symmetric positive
// definite; delta: penetration depth per row, unit m; lambda: normal force per row, unit N).
// W SPD makes the solution unique. Types shared by the two solvers (active_set_lcp.hpp, the
// reference path; inactive_set_lcp.hpp, the path for a constant leading block) and by their
// front, ContactLcp (contact_lcp.hpp).
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace neurosim::interaction {

// One term of a trailing row's column against the constant leading rows (LcpProblem::
// column_terms): the column's entries [offset, offset + length) hold block * coef, summed over the
// row's terms (zero elsewhere).
struct LcpColumnTerm {
  // length x 3, column-major (e.g. Eigen::Matrix<double, Eigen::Dynamic, 3>), unit m/N; nullptr:
  // no term. Whenever a block is passed with a key and address, it must hold the same values to
  // round-off as the last time (e.g. a contact node's sliding columns: written once; evicted and
  // solved again they are the same).
  const double* block{nullptr};
  std::uint64_t key{0};  // names the block (with its address)
  int offset{0};
  int length{0};
  Eigen::Vector3d coef{Eigen::Vector3d::Zero()};  // unitless (e.g. -w n: weight times direction)
};

// One LCP. Rows [0, rows) of the inputs are used; the matrix and vectors may be larger (a
// workspace sized once).
struct LcpProblem {
  const Eigen::MatrixXd* compliance{nullptr};  // W (top-left rows x rows block), unit m/N
  const Eigen::VectorXd* depth{nullptr};       // delta (first rows entries), unit m
  int rows{0};
  // Rows [0, stable_rows) have the same entries of W as in the previous solve (e.g. the constant
  // block of sliding-coupling rows; their delta may change): their active (or inactive) set and
  // its factor are taken over from the previous solve; initial_active then applies to the other
  // rows only.
  int stable_rows{0};
  // Start (optional, first rows entries, nonzero: active), part of the problem: e.g. the rows
  // that penetrate, instead of the rows with delta > 0. The pivoting is finite from any start.
  const std::vector<char>* initial_active{nullptr};
  // Warm start from history (optional, first rows entries, nonzero: active; problems with
  // stable_rows == 0 only, ignored otherwise): e.g. the last step's active set. The answer does
  // not depend on it (active_set_lcp.hpp, the canonical answer): the pivoting from it only
  // proposes an active set, which is taken when its canonical answer is complementary with a
  // margin (LcpOptions::warm_margin); otherwise the solve starts again from initial_active.
  const std::vector<char>* warm_active{nullptr};
  // Optional: the trailing rows' columns against the constant leading rows as terms over fixed
  // blocks, terms_per_row per trailing row (row r: entries [r * terms_per_row, (r + 1) *
  // terms_per_row)). The inactive-set path then keeps G = W_ss^-1 times each block (one O(n_s^2)
  // product per block, reused by every row and solve on it) instead of G times each row's
  // column, which changes whenever a row's weights do. They must agree with W's columns to
  // round-off (each solve's result is checked against W itself).
  const std::vector<LcpColumnTerm>* column_terms{nullptr};
  int terms_per_row{0};
};

// Which solver takes a problem whose stable rows are the constant block (ContactLcp).
enum class LcpPath {
  automatic,     // the inactive-set path when most leading rows start active, else the reference
                 // path (the factor goes to the smaller set; hysteresis)
  reference,     // the active-set reference path always
  inactive_set,  // the inactive-set path whatever the warm start (tests)
};

struct LcpOptions {
  // Relative: to max |delta| for the slack w, to max lambda for the forces.
  double tolerance{1e-12};
  int max_iterations{200};  // pivots (inactive-set path: block-pivoting passes)
  // LcpProblem::warm_active: the active set the warm pivoting ends with is taken only if its
  // canonical answer has every active force above this x max lambda and every inactive slack
  // above this x max |delta| (a nondegenerate solution: the cold start ends with the same set,
  // since the two answers differ by at most about cond(W) x tolerance); else the cold start.
  double warm_margin{1e-6};
  LcpPath path{LcpPath::automatic};
};

struct LcpResult {
  bool converged{false};
  int iterations{0};           // pivots (each one Cholesky of the active block); inactive-set path:
                               // block-pivoting passes (each flips one or more rows)
  int active{0};               // rows with lambda > 0
  double max_violation{0.0};   // max(-w, -lambda, 0) relative to max |delta|
  bool dependent_rows{false};  // a row of the active block was (numerically) dependent
  // LcpProblem::warm_active given: the warm pivoting's set was taken (else the cold start ran
  // after it; iterations counts both).
  bool warm_taken{false};
};

// A block of the inverse of the active block W_AA (unit N/m) between chosen active rows: entry
// (a, b) for LCP rows rows[a], rows[b], a, b < count. Workspace sized by reserve(capacity).
struct ActiveBlockInverse {
  std::vector<int> rows;
  int count{0};
  Eigen::MatrixXd inverse;

  void reserve(int capacity) {
    if (static_cast<int>(rows.size()) >= capacity) return;
    rows.assign(capacity, 0);
    inverse.setZero(capacity, capacity);
  }
};

}  // namespace neurosim::interaction
