// ContactLcp, the front over the two LCP solvers: input checks, the choice of path (hysteresis)
// against the reference path over steps, the fallback for a constant block that is not
// definite, and the contact stiffness against the explicit inverse of the active block.
#include "server/interaction/contact_lcp.hpp"

#include "lcp_test_problems.hpp"

#include <gtest/gtest.h>
#include <Eigen/LU>

#include <limits>
#include <random>
#include <string>

namespace neurosim::interaction {
namespace {

using lcp_testing::ConstantBlockProblem;
using lcp_testing::expect_kkt;
using lcp_testing::options;
using lcp_testing::problem;

TEST(interaction_lcp, RejectsNonFinite) {
  Eigen::MatrixXd w = Eigen::MatrixXd::Identity(2, 2);
  Eigen::VectorXd d(2), lam(2);
  d << std::nan(""), 1.0;
  ContactLcp lcp;
  lcp.reserve(2);
  EXPECT_THROW(lcp.solve(problem(w, d, 2), options(1e-12, 50), lam), std::invalid_argument);
}

TEST(interaction_lcp, RejectsProblemsBeyondTheWorkspace) {
  Eigen::MatrixXd w = Eigen::MatrixXd::Identity(3, 3);
  Eigen::VectorXd d = Eigen::VectorXd::Ones(3), lam(3);
  std::vector<char> short_start(2, 1);
  ContactLcp lcp;
  lcp.reserve(2);
  EXPECT_THROW(lcp.solve(problem(w, d, 3), options(1e-12, 50), lam), std::invalid_argument);
  EXPECT_THROW(lcp.solve(problem(w, d, 2, nullptr, 3), options(1e-12, 50), lam),
               std::invalid_argument);
  lcp.reserve(3);
  EXPECT_THROW(lcp.solve(problem(w, d, 3, &short_start), options(1e-12, 50), lam),
               std::invalid_argument);
  EXPECT_THROW(lcp.solve(LcpProblem{}, options(1e-12, 50), lam), std::invalid_argument);
  // No converged solve: no stiffness.
  const Eigen::Vector3d n = Eigen::Vector3d::UnitX();
  EXPECT_THROW(lcp.contact_stiffness(0, [&](int) { return &n; }), std::logic_error);
}

// Non-finite input is rejected with a constant block too, in the leading rows and the trailing
// rows.
TEST(interaction_lcp, RejectsNonFiniteWithConstantBlock) {
  const int ns = 30, cap = 40;
  ConstantBlockProblem prob(ns, cap, 45);
  Eigen::MatrixXd w;
  prob.make(5, w, false, false);
  ContactLcp fast;
  fast.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  const LcpOptions always = options(1e-12, 50, LcpPath::inactive_set);
  Eigen::VectorXd d = Eigen::VectorXd::Constant(cap, 1e-3), lf(cap);
  d[2] = std::nan("");
  EXPECT_THROW(fast.solve(problem(w, d, ns + 5, nullptr, ns), always, lf), std::invalid_argument);
  d[2] = 1e-3;
  d[ns + 1] = std::numeric_limits<double>::infinity();
  EXPECT_THROW(fast.solve(problem(w, d, ns + 5, nullptr, ns), always, lf), std::invalid_argument);
  d[ns + 1] = 1e-3;
  const LcpResult r = fast.solve(problem(w, d, ns + 5, nullptr, ns), always, lf);
  EXPECT_TRUE(r.converged);
  EXPECT_TRUE(fast.last_solve_inactive_set());
}

// The contact-block entry (row_a, row_b) of the inverse of the active block through the
// stiffness: row_a along x, row_b along y gives K(0, 1) = -inv(a, b) (K(0, 0) = -inv(a, a) for
// a == b).
double inverse_entry(ContactLcp& lcp, int first_row, int row_a, int row_b) {
  const Eigen::Vector3d ex = Eigen::Vector3d::UnitX(), ey = Eigen::Vector3d::UnitY();
  const Eigen::Matrix3d k =
      lcp.contact_stiffness(first_row, [&](int row) -> const Eigen::Vector3d* {
        if (row == row_a) return &ex;
        if (row == row_b) return &ey;
        return nullptr;
      });
  return row_a == row_b ? -k(0, 0) : -k(0, 1);
}

// A sequence of steps with the trailing rows changing every step (and the leading delta now and
// then): the front (inactive-set path when most leading rows are pushed, the reference path when
// few are) gives the reference path's answer, forces and the trailing block of the inverse of
// the active block alike.
TEST(interaction_lcp, InactiveSetMatchesReferenceOverSteps) {
  const int ns = 60, cap = 80;
  ConstantBlockProblem prob(ns, cap, 90);
  Eigen::MatrixXd w;
  prob.make(0, w, false, false);
  ContactLcp fast;
  ActiveSetLcp ref;
  fast.reserve(cap);
  ref.reserve(cap);
  ASSERT_TRUE(fast.set_constant_block(w, ns));
  EXPECT_EQ(fast.constant_rows(), ns);
  ActiveBlockInverse ri;
  ri.reserve(cap);
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
    const LcpResult rf = fast.solve(problem(w, d, n, &warm_f, ns), options(1e-12, 2000), lf);
    const LcpResult rr = ref.solve(problem(w, d, n, &warm_r, ns), options(1e-12, 2000), lr);
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
    // Contact block of the inverse of the active block: every contact row's diagonal entry
    // (zero for a row the reference keeps inactive), every pair of the reference's active rows.
    ref.invert_active(ns, ri);
    auto ref_position = [&](int row) {
      for (int k = 0; k < ri.count; ++k)
        if (ri.rows[k] == row) return k;
      return -1;
    };
    const double scale =
        ri.count > 0 ? ri.inverse.topLeftCorner(ri.count, ri.count).cwiseAbs().maxCoeff() : 0.0;
    for (int a = ns; a < n; ++a) {
      const int ra = ref_position(a);
      const double y = ra >= 0 ? ri.inverse(ra, ra) : 0.0;
      EXPECT_NEAR(inverse_entry(fast, ns, a, a), y, 1e-7 * scale) << what << " row " << a;
    }
    for (int a = 0; a < ri.count; ++a)
      for (int b = 0; b < ri.count; ++b) {
        ASSERT_GE(ref_position(ri.rows[a]), 0);
        ASSERT_GE(ref_position(ri.rows[b]), 0);
        const double x = inverse_entry(fast, ns, ri.rows[a], ri.rows[b]);
        EXPECT_NEAR(x, ri.inverse(a, b), 1e-7 * scale) << what;
        ++checked_inverse;
      }
  }
  EXPECT_GT(checked_inverse, 100);
  EXPECT_GT(inactive_path, 40);  // both paths taken
  EXPECT_LT(inactive_path, 160);
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
  const LcpResult r = lcp.solve(problem(w, d, 6, nullptr, 4), options(1e-12, 50), lam);
  EXPECT_TRUE(r.converged);
  EXPECT_EQ(lam[2], 0.0);
  EXPECT_DOUBLE_EQ(lam[0], 1.0);
  EXPECT_FALSE(lcp.last_solve_inactive_set());
}

// The contact stiffness of each group against -N_g (W_AA^-1)_gg N_g^T from the explicit dense
// inverse of the active block (A: the rows with lambda > 0), on random SPD problems, on both
// paths (reference; inactive set with a constant leading block).
TEST(interaction_lcp, ContactStiffnessMatchesDenseInverse) {
  std::mt19937 rng(31);
  std::normal_distribution<double> g(0.0, 1.0);
  std::uniform_int_distribution<int> pick_group(0, 2);
  const int ns = 12, cap = 30, dim = 40;
  Eigen::MatrixXd lead(ns, dim);
  for (int i = 0; i < ns; ++i)
    for (int j = 0; j < dim; ++j) lead(i, j) = g(rng);
  for (const LcpPath path : {LcpPath::reference, LcpPath::inactive_set}) {
    ContactLcp lcp;
    lcp.reserve(cap);
    int checked = 0;
    for (int trial = 0; trial < 30; ++trial) {
      const int n = ns + 6 + trial % 12;
      Eigen::MatrixXd rows(n, dim);
      rows.topRows(ns) = lead;
      for (int i = ns; i < n; ++i)
        for (int j = 0; j < dim; ++j) rows(i, j) = g(rng);
      Eigen::MatrixXd w = Eigen::MatrixXd::Zero(cap, cap);
      w.topLeftCorner(n, n) =
          1e-4 * (rows * rows.transpose() / dim + 0.05 * Eigen::MatrixXd::Identity(n, n));
      if (trial == 0 && path == LcpPath::inactive_set) {
        ASSERT_TRUE(lcp.set_constant_block(w, ns));
      }
      Eigen::VectorXd d = Eigen::VectorXd::Zero(cap), lam = d;
      for (int i = 0; i < n; ++i) d[i] = 1e-3 * g(rng) + 4e-4;
      std::vector<int> group(cap, -1);
      std::vector<Eigen::Vector3d> normal(cap, Eigen::Vector3d::Zero());
      for (int i = ns; i < n; ++i) {
        group[i] = pick_group(rng);
        normal[i] = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
      }
      const LcpResult r = lcp.solve(problem(w, d, n, nullptr, ns), options(1e-12, 2000, path), lam);
      ASSERT_TRUE(r.converged) << trial;
      EXPECT_EQ(lcp.last_solve_inactive_set(), path == LcpPath::inactive_set) << trial;
      std::vector<int> active;
      for (int i = 0; i < n; ++i)
        if (lam[i] > 0.0) active.push_back(i);
      const int na = static_cast<int>(active.size());
      Eigen::MatrixXd waa(na, na);
      for (int a = 0; a < na; ++a)
        for (int b = 0; b < na; ++b) waa(a, b) = w(active[a], active[b]);
      const Eigen::MatrixXd inv = waa.inverse();
      for (int grp = 0; grp < 3; ++grp) {
        Eigen::Matrix3d want = Eigen::Matrix3d::Zero();
        for (int a = 0; a < na; ++a)
          for (int b = 0; b < na; ++b) {
            if (group[active[a]] != grp || group[active[b]] != grp) continue;
            want -= inv(a, b) * normal[active[a]] * normal[active[b]].transpose();
          }
        const Eigen::Matrix3d got =
            lcp.contact_stiffness(ns, [&](int row) -> const Eigen::Vector3d* {
              EXPECT_GE(row, ns);
              return group[row] == grp ? &normal[row] : nullptr;
            });
        EXPECT_LE((got - want).norm(), 1e-8 * std::max(want.norm(), 1e-300))
            << "trial " << trial << " group " << grp;
        EXPECT_LE((got - got.transpose()).norm(), 1e-12 * std::max(got.norm(), 1e-300));
        if (want.norm() > 0.0) ++checked;
      }
    }
    EXPECT_GT(checked, 40);
  }
}

}  // namespace
}  // namespace neurosim::interaction
