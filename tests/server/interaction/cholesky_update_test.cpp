// drop_factor_row against a fresh factorization: for random SPD matrices of sizes 1 to 12 and
// every dropped position, the updated factor equals the Cholesky factor of the matrix without
// that row and column (lower triangular, positive diagonal, 1e-12 relative), and the rotations
// it reports, applied to the factor with the row deleted, reproduce it (the inactive-set solver
// applies them to its own data). The LCP tests see the factor only through their answers.
#include "server/interaction/cholesky_update.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>
#include <Eigen/QR>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace neurosim::interaction {
namespace {

// A random SPD matrix, condition number around 1e3 (eigenvalues 1e-3..1 in a random basis).
Eigen::MatrixXd random_spd(int n, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Eigen::MatrixXd a(n, n);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j) a(i, j) = u(rng);
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(a);
  const Eigen::MatrixXd q = qr.householderQ();
  Eigen::VectorXd lambda(n);
  for (int i = 0; i < n; ++i) lambda(i) = std::pow(10.0, -3.0 * i / std::max(1, n - 1));
  return q * lambda.asDiagonal() * q.transpose();
}

// m without row and column pos.
Eigen::MatrixXd without(const Eigen::MatrixXd& m, int pos) {
  const int n = static_cast<int>(m.rows());
  Eigen::MatrixXd out(n - 1, n - 1);
  for (int i = 0, r = 0; i < n; ++i) {
    if (i == pos) continue;
    for (int j = 0, c = 0; j < n; ++j) {
      if (j == pos) continue;
      out(r, c++) = m(i, j);
    }
    ++r;
  }
  return out;
}

TEST(interaction_cholesky_update, DroppingAnyRowGivesTheFactorOfTheSmallerMatrix) {
  std::mt19937 rng(20261126);
  int checked = 0;
  for (int k = 2; k <= 12; ++k) {
    const Eigen::MatrixXd a = random_spd(k, rng);
    const Eigen::MatrixXd l_full = a.llt().matrixL();
    for (int pos = 0; pos < k; ++pos) {
      // The solvers keep the factor in a larger buffer: only the leading k x k block is in use.
      Eigen::MatrixXd l = Eigen::MatrixXd::Constant(k + 3, k + 3, 7.0);
      l.topLeftCorner(k, k) = l_full;
      std::vector<double> c(static_cast<std::size_t>(k - 1), 0.0), s(c.size(), 0.0);
      drop_factor_row(l, k, pos, c.data(), s.data());

      const Eigen::MatrixXd smaller = without(a, pos);
      const Eigen::MatrixXd expected = smaller.llt().matrixL();
      const Eigen::MatrixXd got = l.topLeftCorner(k - 1, k - 1);
      EXPECT_LT((got - expected).norm(), 1e-12 * expected.norm()) << "k " << k << ", pos " << pos;
      EXPECT_LT((got * got.transpose() - smaller).norm(), 1e-12 * smaller.norm())
          << "k " << k << ", pos " << pos;
      for (int i = 0; i + 1 < k; ++i) {
        EXPECT_GT(got(i, i), 0.0) << "k " << k << ", pos " << pos;
        for (int j = i + 1; j < k; ++j)  // the upper part and the freed column k-1 are zero
          EXPECT_EQ(l(i, j), 0.0) << "k " << k << ", pos " << pos << ", (" << i << ", " << j << ")";
      }
      // Nothing outside the k x k block is touched.
      EXPECT_EQ(l.rightCols(3).norm(), Eigen::MatrixXd::Constant(k + 3, 3, 7.0).norm());
      EXPECT_EQ(l.bottomRows(3).leftCols(k).norm(), Eigen::MatrixXd::Constant(3, k, 7.0).norm());

      // The rotations: the factor with row pos deleted ((k-1) x k, one entry right of the
      // diagonal below pos), rotated in the column pairs (j, j+1) for j = pos..k-2, is the result.
      Eigen::MatrixXd h(k - 1, k);
      for (int i = 0, r = 0; i < k; ++i)
        if (i != pos) h.row(r++) = l_full.row(i);
      for (int j = pos; j + 1 < k; ++j) {
        const double cj = c[static_cast<std::size_t>(j)], sj = s[static_cast<std::size_t>(j)];
        EXPECT_NEAR(cj * cj + sj * sj, 1.0, 1e-14);
        const Eigen::VectorXd x = h.col(j), y = h.col(j + 1);
        h.col(j) = cj * x + sj * y;
        h.col(j + 1) = -sj * x + cj * y;
      }
      EXPECT_LT((h.leftCols(k - 1) - expected).norm(), 1e-12 * expected.norm());
      EXPECT_LT(h.col(k - 1).norm(), 1e-12 * expected.norm());
      ++checked;
    }
  }
  EXPECT_EQ(checked, 77);  // 2 + 3 + ... + 12 drops
}

// Dropping rows one after another (as the solvers do over many pivots) keeps the factor exact.
TEST(interaction_cholesky_update, RepeatedDropsStayTheFactorOfWhatIsLeft) {
  std::mt19937 rng(7);
  const int n = 10;
  Eigen::MatrixXd a = random_spd(n, rng);
  Eigen::MatrixXd l = a.llt().matrixL();
  std::vector<double> c(n), s(n);
  for (int k = n; k > 1; --k) {
    const int pos = static_cast<int>(rng() % static_cast<unsigned>(k));
    drop_factor_row(l, k, pos, c.data(), s.data());
    a = without(a, pos);
    const Eigen::MatrixXd got = l.topLeftCorner(k - 1, k - 1);
    EXPECT_LT((got * got.transpose() - a).norm(), 1e-12 * a.norm()) << "k " << k;
  }
}

// One row: nothing is left, nothing is written (no rotation).
TEST(interaction_cholesky_update, DroppingTheOnlyRowWritesNothing) {
  Eigen::MatrixXd l = Eigen::MatrixXd::Constant(2, 2, 3.0);
  drop_factor_row(l, 1, 0, nullptr, nullptr);
  EXPECT_EQ(l, Eigen::MatrixXd::Constant(2, 2, 3.0));
}

}  // namespace
}  // namespace neurosim::interaction
