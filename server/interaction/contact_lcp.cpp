#include "server/interaction/contact_lcp.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

void ContactLcp::reserve(int max_rows) {
  if (max_rows <= capacity_) return;
  capacity_ = max_rows;
  reference_.reserve(max_rows);
  inactive_set_.reserve(max_rows);
  inverse_.reserve(max_rows);
  group_.assign(max_rows, 0);
  directions_.assign(max_rows, nullptr);
  inverse_first_row_ = -1;
}

bool ContactLcp::set_constant_block(const Eigen::MatrixXd& w, int rows) {
  last_inactive_set_ = false;
  inverse_first_row_ = -1;
  return inactive_set_.set_constant_block(w, rows);
}

LcpResult ContactLcp::solve(const LcpProblem& problem, const LcpOptions& options,
                            Eigen::VectorXd& lambda) {
  if (problem.compliance == nullptr || problem.depth == nullptr)
    throw std::invalid_argument("ContactLcp::solve: no compliance or depth");
  const Eigen::MatrixXd& w = *problem.compliance;
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows, stable_rows = problem.stable_rows;
  const std::vector<char>* initial_active = problem.initial_active;
  if (initial_active && static_cast<int>(initial_active->size()) < n)
    throw std::invalid_argument("ContactLcp::solve: start shorter than the rows");
  if (problem.warm_active && static_cast<int>(problem.warm_active->size()) < problem.rows)
    throw std::invalid_argument("ContactLcp::solve: warm start shorter than the rows");
  if (n < 0 || n > capacity_ || w.rows() < n || w.cols() < n || delta.size() < n ||
      lambda.size() < n || stable_rows < 0 || stable_rows > n) {
    throw std::invalid_argument("ContactLcp::solve: " + std::to_string(n) +
                                " rows exceed the workspace (" + std::to_string(capacity_) +
                                ") or the inputs");
  }
  converged_ = false;
  inverse_first_row_ = -1;
  lambda.head(n).setZero();
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(delta[i]) || !std::isfinite(w(i, i))) {
      throw std::invalid_argument("ContactLcp::solve: non-finite input at row " +
                                  std::to_string(i));
    }
  }
  const int ns = inactive_set_.constant_rows();
  bool inactive = options.path != LcpPath::reference && ns > 0 && stable_rows == ns &&
                  n - stable_rows <= inactive_set_.trailing_capacity();
  if (inactive) {
    // The smaller of the two sets of leading rows gets the factor: the inactive set above 60 %
    // warm-active leading rows, the active set (reference path) below 40 % (hysteresis: a switch
    // starts the new path's factor from the warm start, O(rows^3) once).
    int warm = 0;
    for (int i = 0; i < stable_rows; ++i)
      warm += (initial_active ? (*initial_active)[i] != 0 : delta[i] > 0.0) ? 1 : 0;
    const bool want = options.path == LcpPath::inactive_set ||
                      (prefer_inactive_set_ ? 5 * warm >= 2 * stable_rows
                                            : 5 * warm > 3 * stable_rows);
    if (want != prefer_inactive_set_) {
      prefer_inactive_set_ = want;
      if (want)
        inactive_set_.forget_factor();
      else
        reference_.forget_factor();
    }
    inactive = prefer_inactive_set_;
  }
  LcpResult result;
  if (inactive) {
    last_inactive_set_ = true;
    // The reference factor (if any) belongs to an older W from now on.
    reference_.forget_factor();
    if (inactive_set_.solve(problem, options, lambda, result)) {
      converged_ = result.converged;
      return result;
    }
    // Numerical trouble in the inactive-set factor: the reference path, from scratch.
    inactive_set_.forget_factor();
  }
  last_inactive_set_ = false;
  result = reference_.solve(problem, options, lambda);
  converged_ = result.converged;
  return result;
}

const ActiveBlockInverse& ContactLcp::active_inverse(int first_row) {
  if (!converged_)
    throw std::logic_error("ContactLcp::contact_stiffness: no converged solve");
  if (first_row != inverse_first_row_) {
    if (last_inactive_set_)
      inactive_set_.invert_active(first_row, inverse_);
    else
      reference_.invert_active(first_row, inverse_);
    inverse_first_row_ = first_row;
  }
  return inverse_;
}

}  // namespace neurosim::interaction
