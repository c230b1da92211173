// InactiveSetLcp (the contact LCP with a constant leading block, W_ss^-1 precomputed) against
// the reference path (ActiveSetLcp) in degenerate steps.
#include "server/interaction/active_set_lcp.hpp"
#include "server/interaction/inactive_set_lcp.hpp"

#include "lcp_test_problems.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

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

// Trailing rows given as column terms over fixed node blocks (LcpProblem::column_terms, as the
// contact step gives them: a row's column against the sliding rows is sum_p B_p c_p with new
// weights every step on the same nodes): the same answer as from W's columns alone, on two
// bodies (terms with an offset), nodes recurring between solves (the kept G B) and new ones.
TEST(interaction_inactive_set_lcp, ColumnTermsGiveTheSameAnswer) {
  // Compliance A over 2 bodies: leading rows [0, ns1) and nodes [0, k0) on body 0, the rest on
  // body 1; A is block-diagonal between the bodies (SPD).
  const int ns = 36, ns1 = 20, nodes = 14, k0 = 8, cap = ns + 12, dim = ns + 3 * nodes + 10;
  const int dofs = ns + 3 * nodes;
  std::mt19937 rng(7);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Eigen::MatrixXd r(dofs, dim);
  for (int i = 0; i < dofs; ++i)
    for (int j = 0; j < dim; ++j) r(i, j) = g(rng);
  Eigen::MatrixXd a = 1e-4 * (r * r.transpose() / dim);
  a.diagonal().array() += 5e-6;
  auto body_of = [&](int dof) { return dof < ns ? (dof < ns1 ? 0 : 1) : ((dof - ns) / 3 < k0 ? 0 : 1); };
  for (int i = 0; i < dofs; ++i)
    for (int j = 0; j < dofs; ++j)
      if (body_of(i) != body_of(j)) a(i, j) = 0.0;
  // Node k's block against its body's leading rows (column-major, length x 3).
  std::vector<Eigen::Matrix<double, Eigen::Dynamic, 3>> blocks(nodes);
  for (int k = 0; k < nodes; ++k) {
    const int o = k < k0 ? 0 : ns1, len = k < k0 ? ns1 : ns - ns1;
    blocks[k] = a.block(o, ns + 3 * k, len, 3);
  }
  InactiveSetLcp with_terms, from_w;
  with_terms.reserve(cap);
  from_w.reserve(cap);
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(cap, cap);
  w.topLeftCorner(ns, ns) = a.topLeftCorner(ns, ns);
  ASSERT_TRUE(with_terms.set_constant_block(w, ns));
  ASSERT_TRUE(from_w.set_constant_block(w, ns));
  std::vector<LcpColumnTerm> terms(3 * (cap - ns));
  int compared = 0;
  for (int step = 0; step < 30; ++step) {
    const int nc = 3 + step % 9;
    const int n = ns + nc;
    // Row q: selector h over the dofs (three nodes of one body, weights w_p times a direction).
    Eigen::MatrixXd h = Eigen::MatrixXd::Zero(nc, dofs);
    for (int q = 0; q < nc; ++q) {
      const int body = q % 2;
      const int first = body == 0 ? 0 : k0, count = body == 0 ? k0 : nodes - k0;
      Eigen::Vector3d m(g(rng), g(rng), g(rng));
      m.normalize();
      double wsum = 0.0;
      double wt[3];
      for (double& x : wt) wsum += (x = 0.1 + u(rng));
      for (int p = 0; p < 3; ++p) {
        // Nodes recur between steps (a slow tool), one new one now and then.
        const int k = first + (q + p + step / 4) % count;
        const Eigen::Vector3d coef = -(wt[p] / wsum) * m;
        h.block(q, ns + 3 * k, 1, 3) += coef.transpose();
        LcpColumnTerm& t = terms[3 * q + p];
        t.block = blocks[k].data();
        t.key = static_cast<std::uint64_t>(k);
        t.offset = body == 0 ? 0 : ns1;
        t.length = body == 0 ? ns1 : ns - ns1;
        t.coef = coef;
      }
    }
    w.block(0, ns, ns, nc) = a.topRows(ns) * h.transpose();
    w.block(ns, 0, nc, ns) = w.block(0, ns, ns, nc).transpose();
    w.block(ns, ns, nc, nc) = h * a * h.transpose();
    w.block(ns, ns, nc, nc).diagonal() *= 1.0 + 1e-3;  // the row compliance in series
    Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lt = d, lw = d;
    for (int i = 0; i < n; ++i) d[i] = 1e-3 * g(rng) + (i >= ns ? 5e-4 : 0.0);
    LcpProblem pt = problem(w, d, n, nullptr, ns);
    pt.column_terms = &terms;
    pt.terms_per_row = 3;
    LcpResult rt, rw;
    const std::string what = "step " + std::to_string(step);
    ASSERT_TRUE(with_terms.solve(pt, options(1e-12, 2000), lt, rt)) << what;
    ASSERT_TRUE(from_w.solve(problem(w, d, n, nullptr, ns), options(1e-12, 2000), lw, rw)) << what;
    ASSERT_TRUE(rt.converged) << what << " " << rt.max_violation;
    ASSERT_TRUE(rw.converged) << what;
    expect_kkt(w, d, lt, n, 1e-8, what);
    const double scale = std::max(1e-300, lw.head(n).cwiseAbs().maxCoeff());
    EXPECT_LE((lt.head(n) - lw.head(n)).cwiseAbs().maxCoeff(), 1e-9 * scale) << what;
    compared += rt.active > ns / 4 ? 1 : 0;
  }
  EXPECT_GT(compared, 10);  // the comparisons had force on them
  // Malformed terms: too few for the rows, or past the constant rows.
  Eigen::VectorXd d = Eigen::VectorXd::Constant(cap, 1e-3), l = d;
  LcpResult res;
  std::vector<LcpColumnTerm> few(2);
  LcpProblem bad = problem(w, d, ns + 3, nullptr, ns);
  bad.column_terms = &few;
  bad.terms_per_row = 3;
  EXPECT_THROW(with_terms.solve(bad, options(1e-12, 200), l, res), std::invalid_argument);
  terms[0].offset = ns - 2;
  bad.column_terms = &terms;
  EXPECT_THROW(with_terms.solve(bad, options(1e-12, 200), l, res), std::invalid_argument);
}

}  // namespace
}  // namespace neurosim::interaction
