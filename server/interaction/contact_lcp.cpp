#include "server/interaction/contact_lcp.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

void ContactLcp::reserve(int max_rows) {
  if (max_rows <= capacity_) return;
  capacity_ = max_rows;
  in_set_.assign(capacity_, 0);
  active_rows_.assign(capacity_, 0);
  chol_.setZero(capacity_, capacity_);
  inverse_.setZero(capacity_, capacity_);
  rhs_.setZero(capacity_);
  sol_.setZero(capacity_);
  w_.setZero(capacity_);
}

int ContactLcp::factor_and_solve(const Eigen::MatrixXd& w, const Eigen::VectorXd& delta) {
  const int k = num_active_;
  // Cholesky of W_AA, column by column (k is a few dozen at most).
  for (int j = 0; j < k; ++j) {
    const int rj = active_rows_[j];
    double d = w(rj, rj);
    for (int p = 0; p < j; ++p) d -= chol_(j, p) * chol_(j, p);
    // A pivot lost to round-off: the row is a combination of the others.
    if (!(d > 1e-12 * w(rj, rj))) return j;
    const double ljj = std::sqrt(d);
    chol_(j, j) = ljj;
    for (int i = j + 1; i < k; ++i) {
      double s = w(active_rows_[i], rj);
      for (int p = 0; p < j; ++p) s -= chol_(i, p) * chol_(j, p);
      chol_(i, j) = s / ljj;
    }
  }
  for (int i = 0; i < k; ++i) {
    double s = delta[active_rows_[i]];
    for (int p = 0; p < i; ++p) s -= chol_(i, p) * rhs_[p];
    rhs_[i] = s / chol_(i, i);
  }
  for (int i = k - 1; i >= 0; --i) {
    double s = rhs_[i];
    for (int p = i + 1; p < k; ++p) s -= chol_(p, i) * sol_[p];
    sol_[i] = s / chol_(i, i);
  }
  return -1;
}

LcpResult ContactLcp::solve(const Eigen::MatrixXd& w, const Eigen::VectorXd& delta, int n,
                            double tolerance, int max_iterations, Eigen::VectorXd& lambda,
                            const std::vector<char>* initial_active) {
  if (initial_active && static_cast<int>(initial_active->size()) < n)
    throw std::invalid_argument("ContactLcp::solve: warm start shorter than the rows");
  if (n > capacity_ || w.rows() < n || w.cols() < n || delta.size() < n || lambda.size() < n) {
    throw std::invalid_argument("ContactLcp::solve: " + std::to_string(n) +
                                " rows exceed the workspace (" + std::to_string(capacity_) +
                                ") or the inputs");
  }
  LcpResult result;
  lambda.head(n).setZero();
  num_active_ = 0;
  if (n == 0) {
    result.converged = true;
    return result;
  }
  double delta_scale = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(delta[i]) || !std::isfinite(w(i, i))) {
      throw std::invalid_argument("ContactLcp::solve: non-finite input at row " +
                                  std::to_string(i));
    }
    delta_scale = std::max(delta_scale, std::abs(delta[i]));
  }
  if (delta_scale == 0.0) {
    result.converged = true;
    return result;
  }
  // 0: inactive, 1: active, 2: blocked (dependent or immovable row, never active).
  for (int i = 0; i < n; ++i) {
    const bool start = initial_active ? (*initial_active)[i] != 0 : delta[i] > 0.0;
    in_set_[i] = w(i, i) > 0.0 ? (start ? 1 : 0) : 2;
  }

  const double tol_w = tolerance * delta_scale;
  for (int it = 0; it < max_iterations; ++it) {
    result.iterations = it + 1;
    num_active_ = 0;
    for (int i = 0; i < n; ++i)
      if (in_set_[i] == 1) active_rows_[num_active_++] = i;
    const int dep = factor_and_solve(w, delta);
    if (dep >= 0) {
      in_set_[active_rows_[dep]] = 2;
      result.dependent_rows = true;
      continue;
    }
    lambda.head(n).setZero();
    double lambda_scale = 0.0;
    for (int j = 0; j < num_active_; ++j) {
      lambda[active_rows_[j]] = sol_[j];
      lambda_scale = std::max(lambda_scale, std::abs(sol_[j]));
    }
    const double tol_l = tolerance * std::max(lambda_scale, 1e-300);
    w_.head(n).noalias() = w.topLeftCorner(n, n) * lambda.head(n);
    w_.head(n) -= delta.head(n);
    // Murty's least-index pivot: the first row violating its sign condition changes sides.
    int flip = -1;
    for (int i = 0; i < n && flip < 0; ++i) {
      if (in_set_[i] == 1 && lambda[i] < -tol_l) flip = i;
      if (in_set_[i] == 0 && w_[i] < -tol_w) flip = i;
    }
    if (flip < 0) {
      result.converged = true;
      break;
    }
    in_set_[flip] = in_set_[flip] == 1 ? 0 : 1;
  }
  // Report the remaining violation whatever happened (blocked rows included).
  double violation = 0.0;
  double lambda_scale = 1e-300;
  for (int i = 0; i < n; ++i) lambda_scale = std::max(lambda_scale, std::abs(lambda[i]));
  w_.head(n).noalias() = w.topLeftCorner(n, n) * lambda.head(n);
  w_.head(n) -= delta.head(n);
  for (int i = 0; i < n; ++i) {
    violation = std::max(violation, -w_[i] / delta_scale);
    violation = std::max(violation, -lambda[i] / lambda_scale);
    if (in_set_[i] == 1 && std::abs(lambda[i]) > 0.0) ++result.active;
  }
  result.max_violation = violation;
  if (result.converged && violation > 1e3 * tolerance) result.converged = false;
  if (!lambda.head(n).allFinite()) result.converged = false;
  return result;
}

void ContactLcp::invert_active() {
  const int k = num_active_;
  // Columns of the identity through the factor.
  for (int c = 0; c < k; ++c) {
    for (int i = 0; i < k; ++i) {
      double s = i == c ? 1.0 : 0.0;
      for (int p = 0; p < i; ++p) s -= chol_(i, p) * rhs_[p];
      rhs_[i] = s / chol_(i, i);
    }
    for (int i = k - 1; i >= 0; --i) {
      double s = rhs_[i];
      for (int p = i + 1; p < k; ++p) s -= chol_(p, i) * inverse_(p, c);
      inverse_(i, c) = s / chol_(i, i);
    }
  }
}

}  // namespace neurosim::interaction
