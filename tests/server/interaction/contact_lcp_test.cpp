// ContactLcp against enumeration of every active set (the LCP with an SPD matrix has exactly one
// solution) and its reporting when it runs out of pivots.
#include "server/interaction/contact_lcp.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

#include <limits>
#include <random>
#include <string>

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

// Warm starts (any initial active set) and a factor kept over a stable leading block give the
// unique solution of the SPD LCP, as a cold start does; the pivots update the factor (rows added
// and removed in any order), so this also checks the updates against a fresh factorization.
TEST(interaction_lcp, WarmStartAndStableRowsMatchColdStart) {
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  std::bernoulli_distribution coin(0.5);
  const int cap = 40;
  ContactLcp warm, cold;
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
    const LcpResult rw = warm.solve(spd, d, n, 1e-12, 500, lw, &start, stable);
    const LcpResult rc = cold.solve(spd, d, n, 1e-12, 500, lc);
    ASSERT_TRUE(rw.converged && rc.converged) << trial;
    EXPECT_LE((lw.head(n) - lc.head(n)).norm(), 1e-9 * std::max(1.0, lc.head(n).norm())) << trial;
    EXPECT_GE(lw.head(n).minCoeff(), 0.0);
    const Eigen::VectorXd slack = spd.topLeftCorner(n, n) * lw.head(n) - d.head(n);
    EXPECT_GE(slack.minCoeff(), -1e-9 * d.head(n).cwiseAbs().maxCoeff()) << trial;
  }
}

TEST(interaction_lcp, RejectsNonFinite) {
  Eigen::MatrixXd w = Eigen::MatrixXd::Identity(2, 2);
  Eigen::VectorXd d(2), lam(2);
  d << std::nan(""), 1.0;
  ContactLcp lcp;
  lcp.reserve(2);
  EXPECT_THROW(lcp.solve(w, d, 2, 1e-12, 50, lam), std::invalid_argument);
}

// ---- Inactive-set path for a constant leading block (set_constant_block) ----

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

void expect_kkt(const Eigen::MatrixXd& w, const Eigen::VectorXd& d, const Eigen::VectorXd& lam,
                int n, double tol, const std::string& what) {
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

// A sequence of steps with the trailing rows changing every step (and the leading delta now and
// then): the inactive-set path gives the reference path's answer, forces and the trailing block
// of the inverse of the active block alike.
TEST(interaction_lcp, InactiveSetMatchesReferenceOverSteps) {
  const int ns = 60, cap = 80;
  ConstantBlockProblem prob(ns, cap, 90);
  Eigen::MatrixXd w;
  prob.make(0, w, false, false);
  ContactLcp fast, ref;
  fast.reserve(cap);
  ref.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  EXPECT_EQ(fast.constant_rows(), ns);
  Eigen::VectorXd ds(ns);
  for (int i = 0; i < ns; ++i) ds[i] = 1e-3 * prob.g(prob.rng) - 3e-4;
  std::vector<char> warm_f(cap, 0), warm_r(cap, 0);
  int checked_inverse = 0, inactive_path = 0;
  for (int step = 0; step < 200; ++step) {
    const int nc = step % 17;
    prob.make(nc, w, false, false);
    // Regimes: most leading rows pushed (inactive-set path), few (reference path), in between.
    if (step % 30 == 29) {
      const double offset = (step / 30) % 3 == 0 ? 1.5e-3 : (step / 30) % 3 == 1 ? -1.2e-3 : 0.0;
      for (int i = 0; i < ns; ++i) ds[i] = 1e-3 * prob.g(prob.rng) + offset;
    }
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lf = d, lr = d;
    d.head(ns) = ds;
    for (int i = ns; i < ns + nc; ++i) d[i] = 1e-3 * prob.g(prob.rng) + 5e-4;
    const int n = ns + nc;
    for (int i = ns; i < n; ++i) warm_f[i] = warm_r[i] = d[i] > 0.0 ? 1 : 0;
    const LcpResult rf = fast.solve(w, d, n, 1e-12, 2000, lf, &warm_f, ns);
    const LcpResult rr = ref.solve(w, d, n, 1e-12, 2000, lr, &warm_r, ns);
    const std::string what = "step " + std::to_string(step);
    if (fast.last_solve_inactive_set()) ++inactive_path;
    ASSERT_TRUE(rf.converged) << what;
    ASSERT_TRUE(rr.converged) << what;
    EXPECT_FALSE(rf.dependent_rows) << what;
    EXPECT_LE((lf.head(n) - lr.head(n)).norm(), 1e-8 * std::max(1e-12, lr.head(n).norm())) << what;
    EXPECT_EQ(rf.active, rr.active) << what;
    EXPECT_LE(rf.max_violation, 1e-9) << what;
    expect_kkt(w, d, lf, n, 1e-9, what);
    for (int i = 0; i < ns; ++i) warm_f[i] = warm_r[i] = lf[i] > 0.0 ? 1 : 0;
    // Contact block of the inverse of the active block.
    fast.invert_active(ns);
    ref.invert_active(ns);
    for (int a = 0; a < fast.num_active(); ++a) {
      if (fast.active_rows()[a] < ns) continue;
      for (int b = 0; b < fast.num_active(); ++b) {
        if (fast.active_rows()[b] < ns) continue;
        int ra = -1, rb = -1;
        for (int k = 0; k < ref.num_active(); ++k) {
          if (ref.active_rows()[k] == fast.active_rows()[a]) ra = k;
          if (ref.active_rows()[k] == fast.active_rows()[b]) rb = k;
        }
        ASSERT_GE(ra, 0);
        ASSERT_GE(rb, 0);
        const double x = fast.active_inverse()(a, b), y = ref.active_inverse()(ra, rb);
        EXPECT_NEAR(x, y,
                    1e-7 * ref.active_inverse()
                               .topLeftCorner(ref.num_active(), ref.num_active())
                               .cwiseAbs()
                               .maxCoeff())
            << what;
        ++checked_inverse;
      }
    }
  }
  EXPECT_GT(checked_inverse, 100);
  EXPECT_GT(inactive_path, 40);  // both paths taken
  EXPECT_LT(inactive_path, 160);
}

// Degenerate steps: dependent trailing rows (a duplicate, a copy of a leading row), a zero row,
// nothing active, everything active; the inactive-set path still solves them.
TEST(interaction_lcp, InactiveSetDegenerateCases) {
  const int ns = 30, cap = 40;
  ConstantBlockProblem prob(ns, cap, 45);
  Eigen::MatrixXd w;
  prob.make(0, w, false, false);
  ContactLcp fast, ref;
  fast.reserve(cap);
  ref.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  fast.use_inactive_set(true, true);
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
    const LcpResult rf = fast.solve(w, d, n, 1e-12, 2000, lf, nullptr, ns);
    const LcpResult rr = ref.solve(w, d, n, 1e-12, 2000, lr, nullptr, ns);
    EXPECT_TRUE(fast.last_solve_inactive_set());
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
  LcpResult r = fast.solve(w, d, ns + 5, 1e-12, 200, lf, nullptr, ns);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.active, 0);
  EXPECT_EQ(lf.head(ns + 5).cwiseAbs().maxCoeff(), 0.0);
  // Everything active: delta = W * (positive lambda).
  Eigen::VectorXd want = Eigen::VectorXd::Zero(cap);
  for (int i = 0; i < ns + 5; ++i) want[i] = 1.0 + 0.01 * i;
  d.setZero();
  d.head(ns + 5) = w.topLeftCorner(ns + 5, ns + 5) * want.head(ns + 5);
  r = fast.solve(w, d, ns + 5, 1e-12, 500, lf, nullptr, ns);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.active, ns + 5);
  EXPECT_LE((lf.head(ns + 5) - want.head(ns + 5)).norm(), 1e-8 * want.norm());
  // And back to nothing active from everything active (carried factor).
  d.setConstant(-1e-3);
  r = fast.solve(w, d, ns + 5, 1e-12, 500, lf, nullptr, ns);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(r.active, 0);
  // Non-finite input is rejected, in the leading rows and the trailing rows.
  d.setConstant(1e-3);
  d[2] = std::nan("");
  EXPECT_THROW(fast.solve(w, d, ns + 5, 1e-12, 50, lf, nullptr, ns), std::invalid_argument);
  d[2] = 1e-3;
  d[ns + 1] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(fast.solve(w, d, ns + 5, 1e-12, 50, lf, nullptr, ns), std::invalid_argument);
  // Too few pivots: reported, not thrown.
  d.setConstant(1e-3);
  r = fast.solve(w, d, ns + 5, 1e-12, 1, lf, nullptr, ns);
  EXPECT_FALSE(r.converged);
}

// A leading block that is not positive definite is refused; the reference path stays in use.
TEST(interaction_lcp, ConstantBlockMustBeDefinite) {
  Eigen::MatrixXd w = Eigen::MatrixXd::Identity(6, 6);
  w(2, 2) = 0.0;
  ContactLcp lcp;
  lcp.reserve(6);
  EXPECT_FALSE(lcp.set_constant_block(w, 4));
  EXPECT_EQ(lcp.constant_rows(), 0);
  Eigen::VectorXd d = Eigen::VectorXd::Constant(6, 1.0), lam(6);
  d[2] = -1.0;  // the immovable row must not be asked to move
  const LcpResult r = lcp.solve(w, d, 6, 1e-12, 50, lam, nullptr, 4);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(lam[2], 0.0);
  EXPECT_DOUBLE_EQ(lam[0], 1.0);
}

}  // namespace
}  // namespace neurosim::interaction
