// InactiveSetLcp (the contact LCP with a constant leading block, W_ss^-1 precomputed) against
// the reference path (ActiveSetLcp) in degenerate steps.
#include "server/interaction/active_set_lcp.hpp"
#include "server/interaction/inactive_set_lcp.hpp"

#include "lcp_test_problems.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace neurosim::interaction {
namespace {

using lcp_testing::ConstantBlockProblem;
using lcp_testing::expect_kkt;
using lcp_testing::options;
using lcp_testing::problem;

// Degenerate steps: dependent trailing rows (a duplicate, a copy of a leading row), a zero row,
// nothing active, everything active; the inactive-set path still solves them.
TEST(interaction_inactive_set_lcp, DegenerateCases) {
  const int ns = 30, cap = 40;
  ConstantBlockProblem prob(ns, cap, 45);
  Eigen::MatrixXd w;
  prob.make(0, w, false, false);
  InactiveSetLcp fast;
  ActiveSetLcp ref;
  fast.reserve(cap);
  ref.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  EXPECT_EQ(fast.constant_rows(), ns);
  EXPECT_EQ(fast.trailing_capacity(), cap - ns);
  LcpResult rf;
  for (int step = 0; step < 40; ++step) {
    const int nc = 3 + step % 6;
    prob.make(nc, w, step % 2 == 0, step % 3 == 0);
    const int n = ns + nc;
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lf = d, lr = d;
    for (int i = 0; i < n; ++i) d[i] = 1e-3 * prob.g(prob.rng);
    if (step % 2 == 0) {
      d[ns + 1] = d[ns];  // the duplicate asks for the same depth
      d[ns + 2] = d[3];
    }
    if (step % 3 == 0) d[n - 1] = -std::abs(d[n - 1]);  // the zero row cannot be asked to move
    const std::string what = "step " + std::to_string(step);
    // true: the inactive-set path solved it (no fallback needed).
    EXPECT_TRUE(fast.solve(problem(w, d, n, nullptr, ns), options(1e-12, 2000), lf, rf));
    const LcpResult rr = ref.solve(problem(w, d, n, nullptr, ns), options(1e-12, 2000), lr);
    if (step % 2 == 0 && lr[ns] > 0.0) {
      EXPECT_TRUE(rf.dependent_rows) << step;
    }
    ASSERT_TRUE(rr.converged) << what << " " << rr.max_violation;
    ASSERT_TRUE(rf.converged) << what << " " << rf.max_violation << " " << rf.iterations;
    expect_kkt(w, d, lf, n, 1e-8, what);
    // Dependent rows split the force in some way; the displacement W lambda is unique.
    const Eigen::VectorXd uf = w.topLeftCorner(n, n) * lf.head(n);
    const Eigen::VectorXd ur = w.topLeftCorner(n, n) * lr.head(n);
    EXPECT_LE((uf - ur).norm(), 1e-7 * std::max(1e-12, ur.norm())) << what;
    if (step % 3 == 0) {
      EXPECT_EQ(lf[n - 1], 0.0) << what;  // the zero row carries nothing
    }
  }
  // Nothing pushes: all rows inactive, lambda = 0.
  prob.make(5, w, false, false);
  Eigen::VectorXd d = Eigen::VectorXd::Constant(cap, -1e-3), lf = Eigen::VectorXd::Ones(cap);
  ASSERT_TRUE(fast.solve(problem(w, d, ns + 5, nullptr, ns), options(1e-12, 200), lf, rf));
  EXPECT_TRUE(rf.converged);
  EXPECT_EQ(rf.active, 0);
  EXPECT_EQ(lf.head(ns + 5).cwiseAbs().maxCoeff(), 0.0);
  // Everything active: delta = W * (positive lambda).
  Eigen::VectorXd want = Eigen::VectorXd::Zero(cap);
  for (int i = 0; i < ns + 5; ++i) want[i] = 1.0 + 0.01 * i;
  d.setZero();
  d.head(ns + 5) = w.topLeftCorner(ns + 5, ns + 5) * want.head(ns + 5);
  ASSERT_TRUE(fast.solve(problem(w, d, ns + 5, nullptr, ns), options(1e-12, 500), lf, rf));
  EXPECT_TRUE(rf.converged);
  EXPECT_EQ(rf.active, ns + 5);
  EXPECT_LE((lf.head(ns + 5) - want.head(ns + 5)).norm(), 1e-8 * want.norm());
  // And back to nothing active from everything active (carried factor).
  d.setConstant(-1e-3);
  ASSERT_TRUE(fast.solve(problem(w, d, ns + 5, nullptr, ns), options(1e-12, 500), lf, rf));
  EXPECT_TRUE(rf.converged);
  EXPECT_EQ(rf.active, 0);
  // Too few pivots: reported, not thrown.
  d.setConstant(1e-3);
  ASSERT_TRUE(fast.solve(problem(w, d, ns + 5, nullptr, ns), options(1e-12, 1), lf, rf));
  EXPECT_FALSE(rf.converged);
}

// The trailing block of the inverse of the active block (K^-1) against the reference path's.
TEST(interaction_inactive_set_lcp, TrailingInverseMatchesReference) {
  const int ns = 40, cap = 55;
  ConstantBlockProblem prob(ns, cap, 60);
  Eigen::MatrixXd w;
  prob.make(0, w, false, false);
  InactiveSetLcp fast;
  ActiveSetLcp ref;
  fast.reserve(cap);
  ref.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  ActiveBlockInverse fi, ri;
  fi.reserve(cap);
  ri.reserve(cap);
  int checked = 0;
  for (int step = 0; step < 20; ++step) {
    const int nc = 4 + step % 10;
    prob.make(nc, w, false, false);
    const int n = ns + nc;
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lf = d, lr = d;
    for (int i = 0; i < n; ++i) d[i] = 1e-3 * prob.g(prob.rng) + 3e-4;
    LcpResult rf;
    ASSERT_TRUE(fast.solve(problem(w, d, n, nullptr, ns), options(1e-12, 2000), lf, rf));
    const LcpResult rr = ref.solve(problem(w, d, n), options(1e-12, 2000), lr);
    ASSERT_TRUE(rf.converged && rr.converged) << step;
    EXPECT_THROW(fast.invert_active(ns - 1, fi), std::logic_error);
    fast.invert_active(ns, fi);
    ref.invert_active(ns, ri);
    ASSERT_EQ(fi.count, ri.count) << step;
    const double scale = ri.inverse.topLeftCorner(ri.count, ri.count).cwiseAbs().maxCoeff();
    for (int a = 0; a < fi.count; ++a)
      for (int b = 0; b < fi.count; ++b) {
        const int ra = static_cast<int>(std::find(ri.rows.begin(), ri.rows.begin() + ri.count,
                                                  fi.rows[a]) - ri.rows.begin());
        const int rb = static_cast<int>(std::find(ri.rows.begin(), ri.rows.begin() + ri.count,
                                                  fi.rows[b]) - ri.rows.begin());
        ASSERT_LT(ra, ri.count);
        ASSERT_LT(rb, ri.count);
        EXPECT_NEAR(fi.inverse(a, b), ri.inverse(ra, rb), 1e-7 * scale) << step;
        ++checked;
      }
  }
  EXPECT_GT(checked, 100);
}

}  // namespace
}  // namespace neurosim::interaction
