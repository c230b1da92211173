// IterativeTie (the paper's iterative baseline) against the monolithic tied system solved
// directly (tied_box_fixtures.hpp): its exact boundary displacement equals the direct solve,
// the relaxed iteration converges to it with a falling residual, a body coupled through the
// iteration gives the direct solve's displacement, an iteration stopped early is counted as
// unconverged, and a body without a tie or bad options are refused.
#include "server/interaction/iterative_tie.hpp"

#include "server/interaction/coupled_body.hpp"
#include "test_support.hpp"
#include "tied_box_fixtures.hpp"

#include <gtest/gtest.h>

namespace neurosim::interaction {
namespace {

using tied_box::make_tied_box;
using tied_box::MonolithicSolver;
using tied_box::TiedBox;

std::unique_ptr<CoupledBody> make_body(const TiedBox& c, const IterativeOptions* iterative) {
  auto body = std::make_unique<CoupledBody>(0, c.host, c.host_material, c.host_fixed);
  body->add_tie(c.def);
  if (iterative != nullptr) body->set_iterative(*iterative);
  body->finalize();
  return body;
}

struct Load {
  std::vector<int> slots;
  std::vector<Eigen::Vector3d> forces_n;
  Eigen::VectorXd host_forces_n;  // the same as nodal forces on A (3 N_A)
};

// Inward forces of 10 mN on every 5th contact slot.
Load make_load(const CoupledBody& body) {
  Load l;
  l.host_forces_n = Eigen::VectorXd::Zero(3 * static_cast<int>(body.host().num_vertices()));
  for (int s = 0; s < static_cast<int>(body.contact_nodes().size()); s += 5) {
    const Eigen::Vector3d f = -0.01 * body.contact_normals()[s];
    l.slots.push_back(s);
    l.forces_n.push_back(f);
    l.host_forces_n.segment<3>(3 * body.contact_nodes()[s]) += f;
  }
  return l;
}

// A's displacement at the tie's boundary nodes (the order of boundary_nodes()).
Eigen::VectorXd boundary_values(const CoupledBody& body, const Eigen::VectorXd& u_host_m) {
  const auto& b = body.boundary_nodes();
  Eigen::VectorXd u(3 * static_cast<int>(b.size()));
  for (std::size_t s = 0; s < b.size(); ++s)
    u.segment<3>(3 * static_cast<int>(s)) = u_host_m.segment<3>(3 * b[s]);
  return u;
}

TEST(interaction_iterative_tie, ExactBoundaryDisplacementEqualsTheMonolithicTiedSolve) {
  const auto owner = make_tied_box();
  const auto body = make_body(*owner, nullptr);
  const Load load = make_load(*body);
  ASSERT_GE(load.slots.size(), 4u);
  const Eigen::VectorXd ref =
      boundary_values(*body, MonolithicSolver(*owner).solve(load.host_forces_n).u_host_m);
  const IterativeTie tie(*body);
  const Eigen::VectorXd u_b = tie.exact(load.slots, load.forces_n);
  ASSERT_GT(ref.norm(), 0.0);
  EXPECT_LE((u_b - ref).norm(), 1e-8 * ref.norm());
}

TEST(interaction_iterative_tie, IterationConvergesToTheMonolithicTiedSolve) {
  const auto owner = make_tied_box();
  const auto body = make_body(*owner, nullptr);
  const Load load = make_load(*body);
  const Eigen::VectorXd ref =
      boundary_values(*body, MonolithicSolver(*owner).solve(load.host_forces_n).u_host_m);
  IterativeOptions o;
  o.max_iterations = 20000;
  o.tolerance = 1e-8;  // the direct solve is the reference: its round-off, not the method's
  const IterativeTie tie(*body, o);
  EXPECT_GT(tie.relaxation(), 0.0);
  EXPECT_LE(tie.relaxation(), 1.0);
  Eigen::VectorXd u_b;
  const IterativeResult r = tie.solve(load.slots, load.forces_n, ref, u_b);
  ASSERT_TRUE(r.converged) << r.iterations << " iterations, residual " << r.residual.back();
  EXPECT_GT(r.iterations, 1) << "the host alone is not already the tie answer";
  ASSERT_EQ(r.residual.size(), static_cast<std::size_t>(r.iterations));
  EXPECT_LE(r.residual.back(), o.tolerance);
  EXPECT_LT(r.residual.back(), 1e-3 * r.residual.front());
  EXPECT_EQ(r.relaxation, tie.relaxation());
  EXPECT_LE((u_b - ref).norm(), 1e-7 * ref.norm());
}

TEST(interaction_iterative_tie, IterativeBodyGivesTheMonolithicDisplacement) {
  const auto owner = make_tied_box();
  IterativeOptions o;
  o.tolerance = 1e-12;
  const auto body = make_body(*owner, &o);
  const Load load = make_load(*body);
  const auto ref = MonolithicSolver(*owner).solve(load.host_forces_n);
  Eigen::VectorXd u_host;
  body->host_displacement(load.slots, load.forces_n, u_host);
  EXPECT_LE((u_host - ref.u_host_m).norm(), 1e-6 * ref.u_host_m.norm());
  // Compliance columns through the iteration: counted, all converged.
  IterativeReport report;
  Eigen::MatrixXd x;
  body->solve_contact_columns(load.slots, x, nullptr, &report);
  EXPECT_GT(report.solves, 0);
  EXPECT_GT(report.max_iterations, 1);
  EXPECT_EQ(report.unconverged, 0);
  // The first column against the direct solve.
  Eigen::VectorXd unit = Eigen::VectorXd::Zero(ref.u_host_m.size());
  unit[3 * body->contact_nodes()[load.slots[0]]] = 1.0;
  const auto col = MonolithicSolver(*owner).solve(unit);
  const auto& free = body->host_solver().free_dofs();
  Eigen::VectorXd col_free(static_cast<int>(free.size()));
  for (std::size_t r = 0; r < free.size(); ++r)
    col_free[static_cast<int>(r)] = col.u_host_m[free[r]];
  EXPECT_LE((x.col(0) - col_free).norm(), 1e-6 * col_free.norm());
}

TEST(interaction_iterative_tie, IterationStoppedEarlyIsCountedUnconverged) {
  const auto owner = make_tied_box();
  IterativeOptions o;
  o.max_iterations = 2;
  o.tolerance = 1e-12;
  const auto body = make_body(*owner, &o);
  const Load load = make_load(*body);
  IterativeReport report;
  Eigen::MatrixXd x;
  body->solve_contact_columns(load.slots, x, nullptr, &report);
  EXPECT_GT(report.solves, 0);
  EXPECT_EQ(report.unconverged, report.solves);
  EXPECT_EQ(report.max_iterations, 2);
  // And the answer is visibly not the tie's.
  const auto ref = MonolithicSolver(*owner).solve(load.host_forces_n);
  Eigen::VectorXd u_host;
  body->host_displacement(load.slots, load.forces_n, u_host);
  EXPECT_GT((u_host - ref.u_host_m).norm(), 1e-6 * ref.u_host_m.norm());
}

TEST(interaction_iterative_tie, BodyWithoutTieAndBadOptionsAreRefused) {
  const auto owner = make_tied_box();
  const TiedBox& c = *owner;
  CoupledBody alone(0, c.host, c.host_material, c.host_fixed);
  alone.finalize();
  EXPECT_NE(testing::message_of([&] { const IterativeTie t(alone); }).find("no tie"),
            std::string::npos);
  CoupledBody body(0, c.host, c.host_material, c.host_fixed);
  IterativeOptions bad;
  bad.tolerance = 0.0;
  EXPECT_THROW(body.set_iterative(bad), std::invalid_argument);
  bad = IterativeOptions{};
  bad.max_iterations = 0;
  EXPECT_THROW(body.set_iterative(bad), std::invalid_argument);
  body.finalize();
  EXPECT_THROW(body.set_iterative(IterativeOptions{}), std::logic_error);
}

}  // namespace
}  // namespace neurosim::interaction
