// Shared by the LCP tests (active_set_lcp_test, inactive_set_lcp_test, contact_lcp_test):
// brute-force solution, SPD problems with a constant leading block, and a KKT check.
#pragma once

#include "server/interaction/lcp_problem.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace neurosim::interaction::lcp_testing {

// Brute force: the active set whose solution satisfies every sign condition (the LCP with an SPD
// matrix has exactly one solution).
inline Eigen::VectorXd enumerate(const Eigen::MatrixXd& w, const Eigen::VectorXd& d) {
  const int n = static_cast<int>(d.size());
  for (int mask = 0; mask < (1 << n); ++mask) {
    std::vector<int> a;
    for (int i = 0; i < n; ++i)
      if (mask & (1 << i)) a.push_back(i);
    Eigen::VectorXd lam = Eigen::VectorXd::Zero(n);
    if (!a.empty()) {
      Eigen::MatrixXd waa(a.size(), a.size());
      Eigen::VectorXd da(a.size());
      for (std::size_t i = 0; i < a.size(); ++i) {
        da[i] = d[a[i]];
        for (std::size_t j = 0; j < a.size(); ++j) waa(i, j) = w(a[i], a[j]);
      }
      const Eigen::VectorXd x = waa.llt().solve(da);
      for (std::size_t i = 0; i < a.size(); ++i) lam[a[i]] = x[i];
    }
    const Eigen::VectorXd slack = w * lam - d;
    if (lam.minCoeff() >= -1e-12 && slack.minCoeff() >= -1e-12 * d.cwiseAbs().maxCoeff())
      return lam;
  }
  ADD_FAILURE() << "no solution found by enumeration";
  return Eigen::VectorXd::Zero(n);
}

// The problem of the arguments the solvers took before LcpProblem (w, delta, rows, warm start,
// stable rows).
inline LcpProblem problem(const Eigen::MatrixXd& w, const Eigen::VectorXd& d, int n,
                          const std::vector<char>* initial_active = nullptr, int stable_rows = 0) {
  return LcpProblem{&w, &d, n, stable_rows, initial_active};
}

inline LcpOptions options(double tolerance, int max_iterations,
                          LcpPath path = LcpPath::automatic) {
  LcpOptions o;
  o.tolerance = tolerance;
  o.max_iterations = max_iterations;
  o.path = path;
  return o;
}

// An SPD matrix whose leading ns x ns block stays the same while the trailing rows change: the
// Gram matrix of fixed leading rows and fresh trailing rows (plus a shift), in a cap x cap
// workspace.
struct ConstantBlockProblem {
  int ns, cap;
  Eigen::MatrixXd lead;  // ns x dim rows of the leading block
  std::mt19937 rng{23};
  std::normal_distribution<double> g{0.0, 1.0};

  ConstantBlockProblem(int ns_, int cap_, int dim) : ns(ns_), cap(cap_), lead(ns_, dim) {
    for (int i = 0; i < ns; ++i)
      for (int j = 0; j < dim; ++j) lead(i, j) = g(rng);
  }
  // Trailing rows: a copy of leading row `copy_lead` (dependent), a duplicate of trailing row 0,
  // or a zero row (cannot move) where asked.
  void make(int nc, Eigen::MatrixXd& w, bool dependent, bool zero_row) {
    const int dim = static_cast<int>(lead.cols());
    Eigen::MatrixXd rows(ns + nc, dim);
    rows.topRows(ns) = lead;
    for (int i = 0; i < nc; ++i)
      for (int j = 0; j < dim; ++j) rows(ns + i, j) = g(rng);
    if (dependent && nc >= 3) {
      rows.row(ns + 1) = rows.row(ns);  // two equal trailing rows
      rows.row(ns + 2) = lead.row(3);   // a trailing row equal to a leading one
    }
    w.setZero(cap, cap);
    Eigen::MatrixXd shift = Eigen::MatrixXd::Identity(ns + nc, ns + nc);
    if (dependent && nc >= 3) shift(ns + 1, ns + 1) = shift(ns + 2, ns + 2) = 0.0;
    w.topLeftCorner(ns + nc, ns + nc) = 1e-4 * (rows * rows.transpose() / dim + 0.05 * shift);
    if (dependent && nc >= 3) {
      // Make row ns + 2 exactly the leading row 3 (it was only its Gram image so far).
      w.row(ns + 2).head(ns + nc) = w.row(3).head(ns + nc);
      w.col(ns + 2).head(ns + nc) = w.col(3).head(ns + nc);
      w(ns + 2, ns + 2) = w(3, 3);
      w.row(ns + 1).head(ns + nc) = w.row(ns).head(ns + nc);
      w.col(ns + 1).head(ns + nc) = w.col(ns).head(ns + nc);
      w(ns + 1, ns + 1) = w(ns, ns);
      w(ns + 1, ns) = w(ns, ns + 1) = w(ns, ns);
      w(ns + 2, 3) = w(3, ns + 2) = w(3, 3);
    }
    if (zero_row && nc >= 1) {
      w.row(ns + nc - 1).setZero();
      w.col(ns + nc - 1).setZero();
    }
  }
};

inline void expect_kkt(const Eigen::MatrixXd& w, const Eigen::VectorXd& d,
                       const Eigen::VectorXd& lam, int n, double tol, const std::string& what) {
  const Eigen::VectorXd slack = w.topLeftCorner(n, n) * lam.head(n) - d.head(n);
  const double ds = std::max(d.head(n).cwiseAbs().maxCoeff(), 1e-300);
  const double ls = std::max(lam.head(n).cwiseAbs().maxCoeff(), 1e-300);
  EXPECT_GE(lam.head(n).minCoeff(), -tol * ls) << what;
  EXPECT_GE(slack.minCoeff(), -tol * ds) << what;
  for (int i = 0; i < n; ++i)
    if (lam[i] > tol * ls) {
      EXPECT_LE(std::abs(slack[i]), tol * ds) << what << " row " << i;
    }
}

}  // namespace neurosim::interaction::lcp_testing
