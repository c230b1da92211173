// ActiveSetLcp (the reference path of the contact LCP) against enumeration of every active set
// (the LCP with an SPD matrix has exactly one solution), its reporting when it runs out of
// pivots, and its warm starts.
#include "server/interaction/active_set_lcp.hpp"

#include "lcp_test_problems.hpp"

#include <gtest/gtest.h>

#include <random>
#include <utility>
#include <vector>

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

// The canonical answer: a warm start from any active set (random, the last problem's, the
// answer's own) gives the cold start's lambda and W_AA^-1 bit for bit, since the set it ends with
// is solved again from scratch in row order; from the answer's own set it takes one pivot. Fails
// without the canonical solve (the pivots' factor order changes the round-off).
TEST(interaction_active_set_lcp, WarmStartFromAnySetGivesTheColdAnswerBitForBit) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  std::bernoulli_distribution coin(0.5);
  const int cap = 32;
  ActiveSetLcp warm, cold;
  warm.reserve(cap);
  cold.reserve(cap);
  ActiveBlockInverse iw, ic;
  iw.reserve(cap);
  ic.reserve(cap);
  std::vector<char> last(cap, 0), start(cap, 0);
  int taken = 0, pivoted = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const int n = 4 + trial % 28;
    Eigen::MatrixXd a(n, n + 3);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n + 3; ++j) a(i, j) = g(rng);
    Eigen::MatrixXd w = Eigen::MatrixXd::Zero(cap, cap);
    w.topLeftCorner(n, n) = 1e-4 * (a * a.transpose() / (n + 3) + 0.02 * Eigen::MatrixXd::Identity(n, n));
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lw = d, lc = d;
    for (int i = 0; i < n; ++i) d[i] = 1e-3 * (g(rng) + 0.5);
    const LcpResult rc = cold.solve(problem(w, d, n), options(1e-10, 500), lc);
    ASSERT_TRUE(rc.converged) << trial;
    cold.invert_active(0, ic);
    std::vector<char> own(cap, 0);
    for (int i = 0; i < n; ++i) own[i] = lc[i] > 0.0 ? 1 : 0;
    for (int i = 0; i < n; ++i) start[i] = coin(rng) ? 1 : 0;
    for (const std::vector<char>* from : {&start, &last, &own}) {
      LcpProblem p = problem(w, d, n);
      p.warm_active = from;
      const LcpResult rw = warm.solve(p, options(1e-10, 500), lw);
      ASSERT_TRUE(rw.converged) << trial;
      for (int i = 0; i < n; ++i) ASSERT_EQ(lw[i], lc[i]) << "trial " << trial << " row " << i;
      warm.invert_active(0, iw);
      ASSERT_EQ(iw.count, ic.count) << trial;
      for (int x = 0; x < ic.count; ++x) {
        ASSERT_EQ(iw.rows[x], ic.rows[x]) << trial;
        for (int y = 0; y < ic.count; ++y) ASSERT_EQ(iw.inverse(x, y), ic.inverse(x, y)) << trial;
      }
      if (rw.warm_taken) ++taken;
      if (from == &own) {
        EXPECT_TRUE(rw.warm_taken) << trial;
        EXPECT_EQ(rw.iterations, 1) << trial;
      }
    }
    last = own;
    // The cold start pivoted (its factor's order was not the rows'): the case the canonical
    // solve is for.
    if (rc.iterations > 1) ++pivoted;
  }
  EXPECT_GE(taken, 300);           // at least every warm start from the answer's own set
  EXPECT_GE(pivoted, 100);
}

// Degenerate problems (a row with w = 0 and lambda = 0 at the solution; duplicate rows): a warm
// start from either side of the degeneracy is not taken (no margin) and the answer is the cold
// start's, bit for bit, and complementary.
TEST(interaction_active_set_lcp, DegenerateWarmStartGivesTheColdAnswer) {
  ActiveSetLcp warm, cold;
  warm.reserve(3);
  cold.reserve(3);
  // Row 1 exactly at zero slack with zero force: lambda = (0.5, 0), w_1 = 0.5 - 0.5 = 0.
  Eigen::MatrixXd w(3, 3);
  w << 2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0;
  Eigen::VectorXd d(3), lw(3), lc(3);
  d << 1.0, 0.5, -1.0;
  // Duplicate rows (two tools on one node): either may carry the force.
  Eigen::MatrixXd dup(3, 3);
  dup << 2.0, 2.0, 0.0, 2.0, 2.0, 0.0, 0.0, 0.0, 1.0;
  Eigen::VectorXd dd(3);
  dd << 1.0, 1.0, 0.5;
  for (const auto& [mat, rhs] : {std::pair{&w, &d}, std::pair{&dup, &dd}}) {
    const LcpResult rc = cold.solve(problem(*mat, *rhs, 3), options(1e-12, 50), lc);
    ASSERT_TRUE(rc.converged);
    lcp_testing::expect_kkt(*mat, *rhs, lc, 3, 1e-12, "cold");
    for (int set = 0; set < 8; ++set) {
      const std::vector<char> from{static_cast<char>(set & 1), static_cast<char>((set >> 1) & 1),
                                   static_cast<char>((set >> 2) & 1)};
      LcpProblem p = problem(*mat, *rhs, 3);
      p.warm_active = &from;
      const LcpResult rw = warm.solve(p, options(1e-12, 50), lw);
      ASSERT_TRUE(rw.converged) << set;
      EXPECT_FALSE(rw.warm_taken) << set;  // the solution has a row without margin
      for (int i = 0; i < 3; ++i) EXPECT_EQ(lw[i], lc[i]) << "set " << set << " row " << i;
    }
  }
}

}  // namespace
}  // namespace neurosim::interaction
