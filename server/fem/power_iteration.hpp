// Dominant eigenvalue of a linear operator by power iteration, for the FEM condition estimate
// (StaticSolver::estimate_condition: K_ff, and K_ff^-1 through the factor) and the iterative
// coupling's relaxation (rho(L_bb K_add) in interaction/iterative_tie.cpp).
#pragma once

#include <Eigen/Core>

#include <cmath>

namespace neurosim::fem {

struct PowerIteration {
  double lambda{0.0};  // the estimate of the dominant eigenvalue
  int iterations{0};   // operator applications
};

// apply(v, w) sets w = A v (w has v's size). Starts from start (any non-zero vector; normalised
// here). Each step estimates lambda by the Rayleigh quotient v . (A v) of the unit iterate v and
// stops when two estimates agree to tolerance (relative) or after max_iterations. For an operator
// whose dominant eigenvalue is real, simple and >= 0 (SPD, or similar to an SPD one), lambda
// converges to it; a zero A v ends the iteration with lambda 0.
template <class Apply>
PowerIteration power_iteration(Apply&& apply, Eigen::VectorXd start, int max_iterations,
                               double tolerance) {
  PowerIteration r;
  Eigen::VectorXd v = std::move(start);
  v.normalize();
  Eigen::VectorXd w(v.size());
  for (int it = 0; it < max_iterations; ++it) {
    apply(static_cast<const Eigen::VectorXd&>(v), w);
    const double next = v.dot(w);
    r.iterations = it + 1;
    const double norm = w.norm();
    if (norm == 0.0) {
      r.lambda = 0.0;
      break;
    }
    v = w / norm;
    if (std::abs(next - r.lambda) <= tolerance * std::abs(next)) {
      r.lambda = next;
      break;
    }
    r.lambda = next;
  }
  return r;
}

}  // namespace neurosim::fem
