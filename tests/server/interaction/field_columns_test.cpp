// FieldColumns: the field of contact forces as a sum of cached full columns equals the sparse
// solve of the same forces (CoupledBody::host_displacement) to 1e-9 relative, on a block without
// ties and on the bundled brain with its tied artery; nodes are solved once and reused, the
// least recently used evicted beyond the capacity (a node solved again gives the same field to
// round-off), and a field with more nodes than the capacity is refused. Through the Simulation:
// a FieldSnapshot's field (the server's field thread) equals the field solved directly.
#include "server/interaction/field_columns.hpp"

#include "server/interaction/simulation.hpp"
#include "server/mesh/generate.hpp"
#include "server/scene/compile.hpp"
#include "tests/test_support.hpp"

#include <gtest/gtest.h>

namespace neurosim::interaction {
namespace {

double relative(const Eigen::VectorXd& a, const Eigen::VectorXd& b) {
  return (a - b).norm() / b.norm();
}

TEST(interaction_field_columns, SumOfColumnsEqualsTheSolveAndEvictsTheLeastRecentlyUsed) {
  mesh::MeshingOptions o;
  o.cell_size_m = 0.01;
  o.seed = 1;
  const mesh::TetMesh m = mesh::generate_box({0, 0, 0}, {0.04, 0.04, 0.04}, o).mesh;
  std::vector<int> fixed;
  for (std::size_t v = 0; v < m.num_vertices(); ++v)
    if (m.vertices()[v].z() < 1e-9) fixed.push_back(static_cast<int>(v));
  fem::Material mat;
  mat.youngs_modulus_pa = 3000.0;
  mat.poisson_ratio = 0.45;
  mat.name = "block";
  CoupledBody body(0, m, mat, fixed);
  body.finalize();
  const int slots = static_cast<int>(body.contact_nodes().size());
  ASSERT_GT(slots, 10);
  EXPECT_EQ(FieldColumns::bytes_per_slot(body), sizeof(double) * 9 * m.num_vertices());
  EXPECT_THROW(FieldColumns(body, 0), std::invalid_argument);

  FieldColumns cols(body, 3);
  fem::SolveWorkspace ws;
  Eigen::VectorXd fast, solved;
  const std::vector<int> a{0, 3, slots - 1};
  const std::vector<Vec3> fa{{0.0, 0.0, -0.1}, {0.02, 0.0, 0.0}, {0.0, -0.05, 0.01}};
  ASSERT_TRUE(cols.field(a, fa, fast, ws));
  body.host_displacement(a, fa, solved);
  EXPECT_LE(relative(fast, solved), 1e-9);
  EXPECT_EQ(cols.columns_solved(), 3u);
  // The same nodes, other forces: a sum, nothing solved.
  const std::vector<Vec3> fb{{0.1, 0.0, 0.0}, {0.0, 0.0, -0.3}, {0.0, 0.0, 0.0}};
  ASSERT_TRUE(cols.field(a, fb, fast, ws));
  body.host_displacement(a, fb, solved);
  EXPECT_LE(relative(fast, solved), 1e-9);
  EXPECT_EQ(cols.columns_solved(), 3u);
  // Nodes 0 and 5: 5 is solved, the least recently used of {3, slots - 1} not in the field goes.
  const Eigen::VectorXd first = fast;
  ASSERT_TRUE(cols.field({3, 5}, {{0.0, 0.0, -0.2}, {0.01, 0.01, 0.0}}, fast, ws));
  body.host_displacement({3, 5}, {{0.0, 0.0, -0.2}, {0.01, 0.01, 0.0}}, solved);
  EXPECT_LE(relative(fast, solved), 1e-9);
  EXPECT_EQ(cols.columns_solved(), 4u);
  EXPECT_EQ(cols.evicted(), 1u);
  EXPECT_EQ(cols.size(), 3u);
  // Back to the first nodes: the evicted one solved again (alone this time: another block, so
  // the last bits may differ), the same field.
  ASSERT_TRUE(cols.field(a, fb, fast, ws));
  EXPECT_LE(relative(fast, first), 1e-12);
  EXPECT_LE(cols.size(), 3u);
  // More nodes than the capacity: refused, the caller solves.
  EXPECT_FALSE(cols.field({0, 1, 2, 3}, std::vector<Vec3>(4, Vec3(0.0, 0.0, -0.1)), fast, ws));
  EXPECT_THROW(cols.field({slots}, {Vec3::Zero()}, fast, ws), std::invalid_argument);
  EXPECT_THROW(cols.field({0}, {}, fast, ws), std::invalid_argument);
  // No force: a zero field.
  ASSERT_TRUE(cols.field({}, {}, fast, ws));
  EXPECT_EQ(fast.size(), 3 * static_cast<Eigen::Index>(m.num_vertices()));
  EXPECT_EQ(fast.norm(), 0.0);
}

// A brain with its tied artery (the tests' 7 mm brain_artery, test_support.hpp brain7_scene: the
// fields need a brain and an artery, not the bundled 5 mm mesh): a press's snapshot fields
// (brain and artery) from the full columns equal those of a sparse solve
// (field_column_budget_mb = 0), twice (the second from kept columns).
TEST(interaction_field_columns, SnapshotFieldsOfAPressEqualTheSolvedFieldsOnTheBrain) {
  const scene::Model model = scene::load_model(neurosim::testing::brain7_scene("brain_artery"));
  SimulationOptions solve_only;
  solve_only.field_column_budget_mb = 0.0;
  auto fast = Simulation::build(model, SimulationOptions{});
  auto slow = Simulation::build(model, solve_only);
  const double tip = model.tools.at(0).tip_radius_m;
  Vec3 lo, hi;
  fast->mesh(0).bounds(lo, hi);
  FieldSnapshot sf, ss;
  for (int k = 0; k < 2; ++k) {
    ToolPose p;
    // Straight down onto the top of the brain near its middle, 2 then 3 mm deep.
    const double depth = 0.002 + 0.001 * k;
    double top = -1e9;
    const Vec3 at(0.5 * (lo.x() + hi.x()) - 0.02, 0.5 * (lo.y() + hi.y()), 0.0);
    for (int v : fast->mesh(0).surface_vertices()) {
      const Vec3& x = fast->mesh(0).vertices()[v];
      if (std::hypot(x.x() - at.x(), x.y() - at.y()) < 0.004) top = std::max(top, x.z());
    }
    ASSERT_GT(top, lo.z());
    p.tip_m = Vec3(at.x(), at.y(), top + tip - depth);
    p.axis = Vec3::UnitZ();
    std::vector<ToolContact> c;
    StepStats st;
    fast->step({p}, c, st);
    ASSERT_TRUE(st.converged);
    ASSERT_GT(c[0].force_n.norm(), 0.0);
    slow->step({p}, c, st);
    fast->snapshot(sf);
    slow->snapshot(ss);
    for (int m = 0; m < fast->num_meshes(); ++m) {
      Eigen::VectorXd uf, us;
      fast->displacements(sf, m, uf);
      slow->displacements(ss, m, us);
      ASSERT_GT(us.norm(), 0.0) << "mesh " << m;
      EXPECT_LE(relative(uf, us), 1e-9) << "mesh " << m << ", press " << k;
    }
    ASSERT_TRUE(sf.bodies.at(0).field_columns != nullptr);
    EXPECT_EQ(ss.bodies.at(0).field_columns, nullptr);
  }
}

}  // namespace
}  // namespace neurosim::interaction
