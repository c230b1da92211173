// ContactLcp against enumeration of every active set (the LCP with an SPD matrix has exactly one
// solution) and its reporting when it runs out of pivots.
#include "server/interaction/contact_lcp.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

#include <random>

namespace neurosim::interaction {
namespace {

// Brute force: the active set whose solution satisfies every sign condition.
Eigen::VectorXd enumerate(const Eigen::MatrixXd& w, const Eigen::VectorXd& d) {
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

TEST(interaction_lcp, MatchesEnumerationOnRandomSpdProblems) {
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  ContactLcp lcp;
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
    const LcpResult r = lcp.solve(w, d, n, 1e-12, 200, lam);
    ASSERT_TRUE(r.converged) << "trial " << trial;
    const Eigen::VectorXd ref = enumerate(w.topLeftCorner(n, n), d.head(n));
    EXPECT_LE((lam.head(n) - ref).norm(), 1e-9 * std::max(1.0, ref.norm())) << "trial " << trial;
    EXPECT_GE(lam.head(n).minCoeff(), 0.0);
  }
}

TEST(interaction_lcp, ReportsNonConvergence) {
  // Every row starts active but only the first may stay: needs more than one pivot.
  Eigen::MatrixXd w(3, 3);
  w << 1.0, 0.9, 0.9, 0.9, 1.0, 0.9, 0.9, 0.9, 1.0;
  Eigen::VectorXd d(3), lam(3);
  d << 1.0, 0.1, 0.1;
  ContactLcp lcp;
  lcp.reserve(3);
  const LcpResult r = lcp.solve(w, d, 3, 1e-12, 1, lam);
  EXPECT_FALSE(r.converged);
  const LcpResult ok = lcp.solve(w, d, 3, 1e-12, 50, lam);
  EXPECT_TRUE(ok.converged);
  EXPECT_NEAR(lam[0], 1.0, 1e-12);
  EXPECT_EQ(lam[1], 0.0);
}

TEST(interaction_lcp, DuplicateRowsAreHandled) {
  Eigen::MatrixXd w(2, 2);
  w << 2.0, 2.0, 2.0, 2.0;  // the same row twice (two tools on one node)
  Eigen::VectorXd d(2), lam(2);
  d << 1.0, 1.0;
  ContactLcp lcp;
  lcp.reserve(2);
  const LcpResult r = lcp.solve(w, d, 2, 1e-12, 50, lam);
  EXPECT_TRUE(r.converged);
  EXPECT_NEAR(lam[0] + lam[1], 0.5, 1e-12);
}

TEST(interaction_lcp, RejectsNonFinite) {
  Eigen::MatrixXd w = Eigen::MatrixXd::Identity(2, 2);
  Eigen::VectorXd d(2), lam(2);
  d << std::nan(""), 1.0;
  ContactLcp lcp;
  lcp.reserve(2);
  EXPECT_THROW(lcp.solve(w, d, 2, 1e-12, 50, lam), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
