// SlidingOperator: W_A equals J_A times coupled compliance columns from independent solves
// (CoupledBody::coupled_displacement with a tie, the host's own solver without), the rows of a
// contact column J_A L[:, slot] equal those of an independent solve, and a bad row is refused
// with a message naming it.
#include "server/interaction/sliding_operator.hpp"

#include "fixed_base_box.hpp"
#include "interaction_fixtures.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/mesh/generate.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <limits>

namespace neurosim::interaction {
namespace {

// Row values n . sum_a w_a u(node_a) of full-dof fields (3N x k), written out from the rows.
Eigen::MatrixXd row_values(const std::vector<HostSlidingRow>& rows, const Eigen::MatrixXd& u) {
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(static_cast<int>(rows.size()), u.cols());
  for (std::size_t k = 0; k < rows.size(); ++k)
    for (int a = 0; a < 3; ++a)
      for (int d = 0; d < 3; ++d)
        out.row(static_cast<int>(k)) +=
            rows[k].weights[a] * rows[k].normal[d] * u.row(3 * rows[k].nodes[a] + d);
  return out;
}

// Full-dof force patterns of the rows (3N x rows): row k pushes its S' point along n.
Eigen::MatrixXd row_forces(const std::vector<HostSlidingRow>& rows, int host_vertices) {
  Eigen::MatrixXd f = Eigen::MatrixXd::Zero(3 * host_vertices, static_cast<int>(rows.size()));
  for (std::size_t k = 0; k < rows.size(); ++k)
    for (int a = 0; a < 3; ++a)
      f.block<3, 1>(3 * rows[k].nodes[a], static_cast<int>(k)) +=
          rows[k].weights[a] * rows[k].normal;
  return f;
}

// Cube with the cylinder TIEd and the rod SLIDING: the host's coupled compliance includes the
// tie (Woodbury), the sliding rows are the rod's.
TEST(interaction_sliding_operator, ComplianceEqualsIndependentCoupledSolvesWithATie) {
  testing::SceneSpec spec;
  spec.rod_kind = "SLIDING";
  const auto sim = Simulation::build(testing::make_scene(spec));
  const CoupledBody* body = sim->body_of(0);
  ASSERT_NE(body, nullptr);
  ASSERT_EQ(body->ties().size(), 1u);
  const SlidingOperator& op = body->sliding();
  const int ns = op.size();
  ASSERT_GT(ns, CoupledBody::kBlockColumns) << "W_A from more than one block solve";
  const int n = static_cast<int>(body->host().num_vertices());
  ASSERT_EQ(op.jacobian().rows(), ns);
  ASSERT_EQ(op.jacobian().cols(), body->host_solver().num_free_dofs());

  // Column k of L J_A^T: one coupled solve per row, each on its own.
  Eigen::MatrixXd u(3 * n, ns);
  const Eigen::MatrixXd f = row_forces(op.rows(), n);
  for (int k = 0; k < ns; ++k) {
    Eigen::VectorXd uk;
    body->coupled_displacement(Eigen::VectorXd(f.col(k)), uk);
    u.col(k) = uk;
  }
  const Eigen::MatrixXd w_ref = row_values(op.rows(), u);
  const Eigen::MatrixXd& w = op.compliance();
  ASSERT_EQ(w.rows(), ns);
  ASSERT_EQ(w.cols(), ns);
  EXPECT_LE((w - w_ref).norm(), 1e-9 * w_ref.norm());
  EXPECT_EQ((w - w.transpose()).norm(), 0.0);
  EXPECT_GT(w.diagonal().minCoeff(), 0.0);
  // The tie matters: without it (host only) W_A is another matrix.
  Eigen::MatrixXd u_host(3 * n, ns);
  for (int k = 0; k < ns; ++k) u_host.col(k) = body->host_solver().solve(Eigen::VectorXd(f.col(k)));
  EXPECT_GT((row_values(op.rows(), u_host) - w_ref).norm(), 1e-3 * w_ref.norm());

  // A contact column's sliding rows: J_A L[:, slot] = rows of a coupled solve with a unit
  // force at the contact node.
  const int slot = static_cast<int>(body->contact_nodes().size()) / 2;
  Eigen::MatrixXd x;
  body->solve_contact_columns({slot}, x);
  const Eigen::MatrixXd rows_of_column = op.apply(x);
  ASSERT_EQ(rows_of_column.rows(), ns);
  ASSERT_EQ(rows_of_column.cols(), 3);
  Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(3 * n, 3), u_col;
  unit.block<3, 3>(3 * body->contact_nodes()[slot], 0).setIdentity();
  body->coupled_displacement(unit, u_col);
  const Eigen::MatrixXd ref = row_values(op.rows(), u_col);
  EXPECT_LE((rows_of_column - ref).norm(), 1e-9 * ref.norm());
  EXPECT_THROW(op.apply(Eigen::MatrixXd::Zero(3, 3)), std::invalid_argument);
}

// A box without ties: W_A = J_A K_ff^-1 J_A^T from the host's own solver; rows with a node on
// the fixed face lose those dofs.
TEST(interaction_sliding_operator, ComplianceWithoutTieIsTheHostCompliance) {
  const fixtures::FixedBaseBox base = fixtures::fixed_base_box(0.01);
  const mesh::TetMesh& box = base.mesh;
  const std::vector<int>& fixed = base.fixed;
  fem::Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  m.name = "box";
  CoupledBody body(0, box, m, fixed);
  // One row per surface triangle touching x = 0.04 or the fixed face z = 0, along a skew unit
  // normal, centroid weights.
  std::vector<HostSlidingRow> rows;
  const Eigen::Vector3d normal = Eigen::Vector3d(1.0, 0.3, -0.2).normalized();
  for (const auto& t : box.surface()) {
    bool side = false;
    for (int v : t) side = side || box.vertices()[v].x() > 0.04 - 1e-9;
    if (!side) continue;
    rows.push_back(HostSlidingRow{{t[0], t[1], t[2]}, {0.5, 0.3, 0.2}, normal});
  }
  ASSERT_GT(rows.size(), 10u);
  EXPECT_EQ(body.add_sliding_rows(rows, "box rows"), 0);
  body.finalize();
  const SlidingOperator& op = body.sliding();
  ASSERT_EQ(op.size(), static_cast<int>(rows.size()));
  const int n = static_cast<int>(box.num_vertices());
  const Eigen::MatrixXd f = row_forces(rows, n);
  Eigen::MatrixXd u(3 * n, op.size());
  for (int k = 0; k < op.size(); ++k)
    u.col(k) = body.host_solver().solve(Eigen::VectorXd(f.col(k)));
  const Eigen::MatrixXd w_ref = row_values(rows, u);
  EXPECT_LE((op.compliance() - w_ref).norm(), 1e-9 * w_ref.norm());
  // J_A has no entry on a fixed dof: a field moving only the fixed nodes gives zero rows.
  Eigen::VectorXd moved = Eigen::VectorXd::Zero(3 * n);
  for (int v : fixed) moved.segment<3>(3 * v) = normal;
  bool touches_fixed = false;
  for (const auto& r : rows)
    for (int v : r.nodes) touches_fixed = touches_fixed || box.vertices()[v].z() < 1e-9;
  ASSERT_TRUE(touches_fixed);
  const auto& free = body.host_solver().free_dofs();
  Eigen::VectorXd moved_free(static_cast<int>(free.size()));
  for (std::size_t r = 0; r < free.size(); ++r) moved_free[static_cast<int>(r)] = moved[free[r]];
  EXPECT_EQ((op.jacobian() * moved_free).norm(), 0.0);
  EXPECT_GT(row_values(rows, moved).norm(), 0.0);
  EXPECT_THROW(body.add_sliding_rows(rows, "late"), std::logic_error);
}

TEST(interaction_sliding_operator, BadRowsAreRefusedNamingTheRow) {
  constexpr int kHost = 10;
  const HostSlidingRow good{{1, 2, 3}, {0.2, 0.3, 0.5}, Eigen::Vector3d::UnitZ()};
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Bad {
    const char* what;
    HostSlidingRow row;
    const char* message;
  };
  const std::vector<Bad> bad{
      {"node -1", {{1, -1, 3}, {0.2, 0.3, 0.5}, Eigen::Vector3d::UnitZ()}, "(host node or weight)"},
      {"node past the end",
       {{1, 2, kHost}, {0.2, 0.3, 0.5}, Eigen::Vector3d::UnitZ()},
       "(host node or weight)"},
      {"NaN weight",
       {{1, 2, 3}, {0.2, nan, 0.5}, Eigen::Vector3d::UnitZ()},
       "(host node or weight)"},
      {"negative weight",
       {{1, 2, 3}, {-0.2, 0.7, 0.5}, Eigen::Vector3d::UnitZ()},
       "(host node or weight)"},
      {"weights sum 1.1",
       {{1, 2, 3}, {0.3, 0.3, 0.5}, Eigen::Vector3d::UnitZ()},
       "has weights summing to 1.1"},
      {"zero normal", {{1, 2, 3}, {0.2, 0.3, 0.5}, Eigen::Vector3d::Zero()}, "not unit"},
      {"infinite normal", {{1, 2, 3}, {0.2, 0.3, 0.5}, Eigen::Vector3d(0.0, inf, 0.0)}, "not unit"},
      {"NaN normal", {{1, 2, 3}, {0.2, 0.3, 0.5}, Eigen::Vector3d(nan, 0.0, 1.0)}, "not unit"},
      {"normal of length 2",
       {{1, 2, 3}, {0.2, 0.3, 0.5}, 2.0 * Eigen::Vector3d::UnitX()},
       "not unit"},
  };
  check_sliding_rows({good, good}, kHost, "fine");  // no throw
  for (const auto& b : bad) {
    const std::vector<HostSlidingRow> rows{good, good, b.row, good};
    std::string m;
    try {
      check_sliding_rows(rows, kHost, "coupling X / Y");
    } catch (const std::invalid_argument& e) {
      m = e.what();
    }
    EXPECT_EQ(m.rfind("coupling X / Y: ", 0), 0u) << b.what << ": " << m;
    EXPECT_NE(m.find("sliding row 2 "), std::string::npos) << b.what << ": " << m;
    EXPECT_NE(m.find(b.message), std::string::npos) << b.what << ": " << m;
  }
}

TEST(interaction_sliding_operator, BodyAndOperatorRefuseBadRows) {
  const fixtures::FixedBaseBox base = fixtures::fixed_base_box(0.02);
  const mesh::TetMesh& box = base.mesh;
  const std::vector<int>& fixed = base.fixed;
  fem::Material m;
  m.youngs_modulus_pa = 3000.0;
  m.poisson_ratio = 0.45;
  CoupledBody body(0, box, m, fixed);
  const int n = static_cast<int>(box.num_vertices());
  mesh::Tri t = box.surface().front();
  for (const auto& tri : box.surface()) {  // a triangle off the fixed face: its row moves
    bool free = true;
    for (int v : tri) free = free && box.vertices()[v].z() > 1e-9;
    if (free) {
      t = tri;
      break;
    }
  }
  const HostSlidingRow good{{t[0], t[1], t[2]}, {0.2, 0.3, 0.5}, Eigen::Vector3d::UnitZ()};
  HostSlidingRow bad = good;
  bad.nodes[0] = n;
  // A refused call adds nothing: the next call's rows start where they would have.
  EXPECT_EQ(body.add_sliding_rows({good}, "first"), 0);
  const std::string m1 = neurosim::testing::message_of([&] {
    body.add_sliding_rows({good, bad}, "second");
  });
  EXPECT_NE(m1.find("second: bad sliding row 1 "), std::string::npos) << m1;
  EXPECT_EQ(body.add_sliding_rows({good}, "third"), 1);
  // The operator checks its rows too, and its definition.
  const auto solve = [&](const Eigen::MatrixXd& b, Eigen::MatrixXd& x) {
    body.host_solver().solve_reduced(b, x);
  };
  const std::string m2 = neurosim::testing::message_of([&] {
    SlidingOperator op(SlidingOperatorDefinition{{good, bad}, &body.host_solver(), solve, 8});
  });
  EXPECT_NE(m2.find("bad sliding row 1 "), std::string::npos) << m2;
  EXPECT_THROW(SlidingOperator(SlidingOperatorDefinition{{good}, nullptr, solve, 8}),
               std::invalid_argument);
  EXPECT_THROW(SlidingOperator(SlidingOperatorDefinition{{good}, &body.host_solver(), solve, 0}),
               std::invalid_argument);
  EXPECT_THROW(SlidingOperator(SlidingOperatorDefinition{{good}, &body.host_solver(), {}, 8}),
               std::invalid_argument);
  const SlidingOperator op(SlidingOperatorDefinition{{good}, &body.host_solver(), solve, 8});
  EXPECT_EQ(op.size(), 1);
  EXPECT_GT(op.compliance()(0, 0), 0.0);
}

}  // namespace
}  // namespace neurosim::interaction
