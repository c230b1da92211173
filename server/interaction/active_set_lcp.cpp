#include "server/interaction/active_set_lcp.hpp"

#include "server/interaction/cholesky_update.hpp"

#include <algorithm>
#include <cmath>

namespace neurosim::interaction {

void ActiveSetLcp::reserve(int max_rows) {
  if (max_rows <= capacity_) return;
  capacity_ = max_rows;
  factor_valid_ = false;
  num_active_ = 0;
  in_set_.assign(capacity_, 0);
  active_rows_.assign(capacity_, 0);
  chol_.setZero(capacity_, capacity_);
  columns_.setZero(capacity_, capacity_);
  position_.assign(capacity_, 0);
  rhs_.setZero(capacity_);
  sol_.setZero(capacity_);
  z_.setZero(capacity_);
  w_.setZero(capacity_);
}

bool ActiveSetLcp::append_row(const Eigen::MatrixXd& w, int row) {
  const int k = num_active_;
  // New factor row: L y = W_A,row, d = W_row,row - |y|^2.
  auto y = rhs_.head(k);
  for (int i = 0; i < k; ++i) y[i] = w(active_rows_[i], row);
  chol_.topLeftCorner(k, k).triangularView<Eigen::Lower>().solveInPlace(y);
  const double d = w(row, row) - y.squaredNorm();
  // A pivot lost to round-off: the row is a combination of the others.
  if (!(d > 1e-12 * w(row, row))) return false;
  chol_.row(k).head(k) = y.transpose();
  chol_(k, k) = std::sqrt(d);
  active_rows_[k] = row;
  num_active_ = k + 1;
  return true;
}

void ActiveSetLcp::remove_position(int pos) {
  const int k = num_active_;
  for (int i = pos; i + 1 < k; ++i) active_rows_[i] = active_rows_[i + 1];
  drop_factor_row(chol_, k, pos, nullptr, nullptr);
  num_active_ = k - 1;
}

void ActiveSetLcp::forward_from(const Eigen::VectorXd& delta, int from) {
  const int k = num_active_;
  if (from >= k) return;
  // z = L^-1 delta_A below position `from` (z above it is unchanged by the last pivot).
  auto tail = z_.segment(from, k - from);
  for (int i = from; i < k; ++i) tail[i - from] = delta[active_rows_[i]];
  if (from > 0) tail.noalias() -= chol_.block(from, 0, k - from, from) * z_.head(from);
  chol_.block(from, from, k - from, k - from).triangularView<Eigen::Lower>().solveInPlace(tail);
}

void ActiveSetLcp::back_solve() {
  const int k = num_active_;
  auto x = sol_.head(k);
  x = z_.head(k);
  chol_.topLeftCorner(k, k).triangularView<Eigen::Lower>().transpose().solveInPlace(x);
}

LcpResult ActiveSetLcp::solve(const LcpProblem& problem, const LcpOptions& options,
                              Eigen::VectorXd& lambda) {
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows;
  lambda.head(n).setZero();
  double delta_scale = 0.0;  // max |delta|, unit m: the scale of the slack tolerance
  for (int i = 0; i < n; ++i) delta_scale = std::max(delta_scale, std::abs(delta[i]));
  LcpResult result;
  if (delta_scale == 0.0) {
    // Nothing pushes: no row active (the kept stable rows' factor is emptied too).
    const bool reuse = problem.stable_rows > 0 && factor_valid_ &&
                       factored_rows_ >= problem.stable_rows && solves_since_factor_ < 1000;
    solves_since_factor_ = reuse ? solves_since_factor_ + 1 : 0;
    for (int i = 0; i < n; ++i) in_set_[i] = 0;
    num_active_ = 0;
    factor_valid_ = true;
    factored_rows_ = n;
    result.converged = true;
    return result;
  }
  // The canonical answer (no stable rows: nothing is kept from the solve before).
  const bool canonical = problem.stable_rows == 0;
  int warm_iterations = 0;
  if (canonical && problem.warm_active != nullptr) {
    result = pivot(problem, options, problem.warm_active, delta_scale, lambda);
    if (result.converged && !result.dependent_rows &&
        settle(problem, options, delta_scale, options.warm_margin, result.iterations > 1,
               lambda)) {
      result.warm_taken = true;
      finish(problem, options, delta_scale, lambda, result);
      return result;
    }
    warm_iterations = result.iterations;
  }
  result = pivot(problem, options, problem.initial_active, delta_scale, lambda);
  if (canonical && result.converged &&
      !settle(problem, options, delta_scale, -1.0, result.iterations > 1, lambda)) {
    // At the tolerance's edge the set's own answer is not complementary: the pivots' answer
    // (the same from the same start).
    result = pivot(problem, options, problem.initial_active, delta_scale, lambda);
  }
  result.iterations += warm_iterations;
  finish(problem, options, delta_scale, lambda, result);
  return result;
}

LcpResult ActiveSetLcp::pivot(const LcpProblem& problem, const LcpOptions& options,
                              const std::vector<char>* start_active, double delta_scale,
                              Eigen::VectorXd& lambda) {
  const Eigen::MatrixXd& w = *problem.compliance;
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows, stable_rows = problem.stable_rows;
  const double tolerance = options.tolerance;
  LcpResult result;
  lambda.head(n).setZero();
  // Warm start: keep the previous factor's rows below stable_rows (refactored from scratch now
  // and then, so round-off of the updates cannot pile up).
  const bool reuse = stable_rows > 0 && factor_valid_ && factored_rows_ >= stable_rows &&
                     solves_since_factor_ < 1000;
  for (int i = 0; i < n; ++i) in_set_[i] = 0;
  if (reuse) {
    ++solves_since_factor_;
    for (int p = num_active_ - 1; p >= 0; --p) {
      if (active_rows_[p] >= stable_rows)
        remove_position(p);
      else
        in_set_[active_rows_[p]] = 1;
    }
  } else {
    solves_since_factor_ = 0;
    num_active_ = 0;
  }
  factor_valid_ = true;
  factored_rows_ = n;
  // 0: inactive, 1: active, 2: blocked (dependent or immovable row, never active).
  for (int i = reuse ? stable_rows : 0; i < n; ++i) {
    const bool start = start_active ? (*start_active)[i] != 0 : delta[i] > 0.0;
    if (!(w(i, i) > 0.0)) {
      in_set_[i] = 2;
    } else if (start) {
      in_set_[i] = 1;
      if (!append_row(w, i)) {
        in_set_[i] = 2;
        result.dependent_rows = true;
      }
    }
  }

  const double tol_w = tolerance * delta_scale;
  // Forward solution z = L^-1 delta_A kept over the pivots: valid below position `valid`.
  int valid = 0;
  for (int it = 0; it < options.max_iterations; ++it) {
    result.iterations = it + 1;
    forward_from(delta, valid);
    valid = num_active_;
    back_solve();
    lambda.head(n).setZero();
    double lambda_scale = 0.0;
    for (int j = 0; j < num_active_; ++j) {
      lambda[active_rows_[j]] = sol_[j];
      lambda_scale = std::max(lambda_scale, std::abs(sol_[j]));
    }
    const double tol_l = tolerance * std::max(lambda_scale, 1e-300);
    // Murty's least-index pivot: the first row violating its sign condition changes sides
    // (w = W lambda - delta only where it is needed: inactive rows, in index order).
    int flip = -1;
    for (int i = 0; i < n && flip < 0; ++i) {
      if (in_set_[i] == 1 && lambda[i] < -tol_l) flip = i;
      if (in_set_[i] == 0 && w.col(i).head(n).dot(lambda.head(n)) - delta[i] < -tol_w) flip = i;
    }
    if (flip < 0) {
      result.converged = true;
      break;
    }
    if (in_set_[flip] == 1) {
      in_set_[flip] = 0;
      for (int p = 0; p < num_active_; ++p)
        if (active_rows_[p] == flip) {
          remove_position(p);
          valid = std::min(valid, p);
          break;
        }
    } else if (append_row(w, flip)) {
      in_set_[flip] = 1;
      valid = std::min(valid, num_active_ - 1);
    } else {
      in_set_[flip] = 2;
      result.dependent_rows = true;
    }
  }
  return result;
}

bool ActiveSetLcp::settle(const LcpProblem& problem, const LcpOptions& options,
                          double delta_scale, double margin, bool refactor,
                          Eigen::VectorXd& lambda) {
  const Eigen::MatrixXd& w = *problem.compliance;
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows;
  // The set's factor from scratch with its rows in index order (unless the pivoting built it
  // so and never pivoted: then it is this factor already, bit for bit), and its answer.
  if (refactor) {
    num_active_ = 0;
    for (int i = 0; i < n; ++i) {
      if (in_set_[i] == 1 && !append_row(w, i)) {
        factor_valid_ = false;
        return false;
      }
    }
    forward_from(delta, 0);
    back_solve();
    lambda.head(n).setZero();
    for (int j = 0; j < num_active_; ++j) lambda[active_rows_[j]] = sol_[j];
  }
  double lambda_scale = 0.0;
  for (int j = 0; j < num_active_; ++j) lambda_scale = std::max(lambda_scale, std::abs(sol_[j]));
  // Complementary: within the tolerance as the pivoting (margin < 0), or strictly, above
  // margin x the scales.
  const bool strict = margin >= 0.0;
  const double bound_l =
      strict ? margin * lambda_scale : -options.tolerance * std::max(lambda_scale, 1e-300);
  const double bound_w = strict ? margin * delta_scale : -options.tolerance * delta_scale;
  auto holds = [strict](double v, double bound) { return strict ? v > bound : v >= bound; };
  for (int i = 0; i < n; ++i) {
    if (in_set_[i] == 1 && !holds(lambda[i], bound_l)) return false;
    if (in_set_[i] == 0 && !holds(w.col(i).head(n).dot(lambda.head(n)) - delta[i], bound_w))
      return false;
  }
  return true;
}

void ActiveSetLcp::finish(const LcpProblem& problem, const LcpOptions& options,
                          double delta_scale, Eigen::VectorXd& lambda, LcpResult& result) {
  const Eigen::MatrixXd& w = *problem.compliance;
  const Eigen::VectorXd& delta = *problem.depth;
  const int n = problem.rows;
  // Report the remaining violation whatever happened (blocked rows included).
  double violation = 0.0;
  double lambda_scale = 1e-300;
  for (int i = 0; i < n; ++i) lambda_scale = std::max(lambda_scale, std::abs(lambda[i]));
  w_.head(n).noalias() = w.topLeftCorner(n, n) * lambda.head(n);
  w_.head(n) -= delta.head(n);
  result.active = 0;
  for (int i = 0; i < n; ++i) {
    violation = std::max(violation, -w_[i] / delta_scale);
    violation = std::max(violation, -lambda[i] / lambda_scale);
    if (in_set_[i] == 1 && std::abs(lambda[i]) > 0.0) ++result.active;
  }
  result.max_violation = violation;
  if (result.converged && violation > 1e3 * options.tolerance) result.converged = false;
  if (!lambda.head(n).allFinite()) {
    result.converged = false;
    factor_valid_ = false;
  }
}

void ActiveSetLcp::invert_active(int first_row, ActiveBlockInverse& out) {
  const int k = num_active_;
  int m = 0;
  for (int c = 0; c < k; ++c) {
    if (active_rows_[c] < first_row) continue;
    auto z = columns_.col(m);
    for (int i = c; i < k; ++i) {
      double s = i == c ? 1.0 : 0.0;
      for (int p = c; p < i; ++p) s -= chol_(i, p) * z[p];
      z[i] = s / chol_(i, i);
    }
    position_[m] = c;
    out.rows[m] = active_rows_[c];
    ++m;
  }
  out.count = m;
  for (int a = 0; a < m; ++a)
    for (int b = 0; b <= a; ++b) {
      const int from = std::max(position_[a], position_[b]);
      const double v =
          columns_.col(a).segment(from, k - from).dot(columns_.col(b).segment(from, k - from));
      out.inverse(a, b) = v;
      out.inverse(b, a) = v;
    }
}

}  // namespace neurosim::interaction
