// ActiveSetLcp (the reference path of the contact LCP) against enumeration of every active set
// (the LCP with an SPD matrix has exactly one solution), its reporting when it runs out of
// pivots, and its warm starts.
#include "server/interaction/active_set_lcp.hpp"

#include "lcp_test_problems.hpp"

#include <gtest/gtest.h>

#include <random>

namespace neurosim::interaction {
namespace {

using lcp_testing::enumerate;
using lcp_testing::options;
using lcp_testing::problem;

TEST(interaction_active_set_lcp, MatchesEnumerationOnRandomSpdProblems) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  ActiveSetLcp lcp;
  lcp.reserve(10);
  for (int trial = 0; trial < 200; ++trial) {
    const int n = 1 + trial % 8;
    Eigen::MatrixXd a(n, n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) a(i, j) = g(rng);
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(10, 10);
    w.topLeftCorner(n, n) = 1e-4 * (a * a.transpose() + 0.1 * Eigen::MatrixXd::Identity(n, n));
    Eigen::VectorXd d = Eigen::VectorXd::Zero(10), lam = Eigen::VectorXd::Zero(10);
    for (int i = 0; i < n; ++i) d[i] = 1e-3 * g(rng);
    const LcpResult r = lcp.solve(problem(w, d, n), options(1e-12, 200), lam);
    ASSERT_TRUE(r.converged) << "trial " << trial;
    const Eigen::VectorXd ref = enumerate(w.topLeftCorner(n, n), d.head(n));
    EXPECT_LE((lam.head(n) - ref).norm(), 1e-9 * std::max(1.0, ref.norm())) << "trial " << trial;
    EXPECT_GE(lam.head(n).minCoeff(), 0.0);
  }
}

TEST(interaction_active_set_lcp, ReportsNonConvergence) {
  // Every row starts active but only the first may stay: needs more than one pivot.
  Eigen::MatrixXd w(3, 3);
  w << 1.0, 0.9, 0.9, 0.9, 1.0, 0.9, 0.9, 0.9, 1.0;
  Eigen::VectorXd d(3), lam(3);
  d << 1.0, 0.1, 0.1;
  ActiveSetLcp lcp;
  lcp.reserve(3);
  const LcpResult r = lcp.solve(problem(w, d, 3), options(1e-12, 1), lam);
  EXPECT_FALSE(r.converged);
  const LcpResult ok = lcp.solve(problem(w, d, 3), options(1e-12, 50), lam);
  EXPECT_TRUE(ok.converged);
  EXPECT_NEAR(lam[0], 1.0, 1e-12);
  EXPECT_EQ(lam[1], 0.0);
}

TEST(interaction_active_set_lcp, DuplicateRowsAreHandled) {
  Eigen::MatrixXd w(2, 2);
  w << 2.0, 2.0, 2.0, 2.0;  // the same row twice (two tools on one node)
  Eigen::VectorXd d(2), lam(2);
  d << 1.0, 1.0;
  ActiveSetLcp lcp;
  lcp.reserve(2);
  const LcpResult r = lcp.solve(problem(w, d, 2), options(1e-12, 50), lam);
  EXPECT_TRUE(r.converged);
  EXPECT_NEAR(lam[0] + lam[1], 0.5, 1e-12);
}

// Warm starts (any initial active set) and a factor kept over a stable leading block give the
// unique solution of the SPD LCP, as a cold start does; the pivots update the factor (rows added
// and removed in any order), so this also checks the updates against a fresh factorization.
TEST(interaction_active_set_lcp, WarmStartAndStableRowsMatchColdStart) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  std::bernoulli_distribution coin(0.5);
  const int cap = 40;
  ActiveSetLcp warm, cold;
  warm.reserve(cap);
  cold.reserve(cap);
  const int stable = 25;
  Eigen::MatrixXd a(cap, cap);
  for (int i = 0; i < cap; ++i)
    for (int j = 0; j < cap; ++j) a(i, j) = g(rng);
  Eigen::VectorXd d0(stable);
  for (int i = 0; i < stable; ++i) d0[i] = 1e-3 * g(rng);
  for (int trial = 0; trial < 50; ++trial) {
    // The stable block keeps its rows of W and its delta; the trailing rows change every trial.
    const int n = stable + trial % 15;
    Eigen::MatrixXd b(n - stable, cap);
    for (int i = 0; i < b.rows(); ++i)
      for (int j = 0; j < cap; ++j) b(i, j) = g(rng);
    // Positive definite: the Gram matrix of the rows [a_stable; b] plus a shift.
    Eigen::MatrixXd rows(n, cap);
    rows.topRows(stable) = a.topRows(stable);
    rows.bottomRows(n - stable) = b;
    Eigen::MatrixXd spd = Eigen::MatrixXd::Zero(cap, cap);
    spd.topLeftCorner(n, n) =
        1e-4 * (rows * rows.transpose() / cap + 0.05 * Eigen::MatrixXd::Identity(n, n));
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lw = d, lc = d;
    d.head(stable) = d0;
    for (int i = stable; i < n; ++i) d[i] = 1e-3 * g(rng);
    std::vector<char> start(cap, 0);
    for (int i = 0; i < n; ++i) start[i] = coin(rng) ? 1 : 0;
    const LcpResult rw = warm.solve(problem(spd, d, n, &start, stable), options(1e-12, 500), lw);
    const LcpResult rc = cold.solve(problem(spd, d, n), options(1e-12, 500), lc);
    ASSERT_TRUE(rw.converged && rc.converged) << trial;
    EXPECT_LE((lw.head(n) - lc.head(n)).norm(), 1e-9 * std::max(1.0, lc.head(n).norm())) << trial;
    EXPECT_GE(lw.head(n).minCoeff(), 0.0);
    const Eigen::VectorXd slack = spd.topLeftCorner(n, n) * lw.head(n) - d.head(n);
    EXPECT_GE(slack.minCoeff(), -1e-9 * d.head(n).cwiseAbs().maxCoeff()) << trial;
  }
}

}  // namespace
}  // namespace neurosim::interaction
