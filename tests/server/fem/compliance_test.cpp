// Compliance columns and blocks: equal to solves with unit forces, symmetric (Maxwell-Betti),
// block solves equal single solves, fixed dofs give zero columns, cache references are stable.
#include "server/fem/compliance.hpp"
#include "fem_test_meshes.hpp"

#include <gtest/gtest.h>
#include <Eigen/Cholesky>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

class FemCompliance : public ::testing::Test {
 protected:
  mesh::TetMesh mesh_ = box_mesh(BoxSpec{4, 4, 3, {0, 0, 0}, {0.04, 0.04, 0.03}, 0.2, 21});
  std::vector<int> bottom_ =
      nodes_where(mesh_, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  StaticSolver solver_{mesh_, MaterialMap::uniform({1e6, 0.4, "brain"}), bottom_};
};

TEST_F(FemCompliance, ColumnIsDisplacementForUnitForce) {
  Compliance c(solver_);
  const int dof = 3 * 60 + 2;
  EXPECT_EQ(c.find_column(dof), nullptr);
  const Eigen::VectorXd& col = c.column(dof);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver_.num_dofs());
  f[dof] = 1.0;
  EXPECT_LE(testing::rel_max_diff(col, solver_.solve(f)), 1e-14);
  EXPECT_EQ(c.find_column(dof), &col);
  EXPECT_EQ(&c.column(dof), &col) << "second lookup must come from the cache";
  EXPECT_GT(col[dof], 0.0);  // compliance diagonal is positive
  // Fixed dof: zero column, nothing cached.
  const Eigen::VectorXd& z = c.column(3 * bottom_[0] + 1);
  EXPECT_EQ(z.norm(), 0.0);
  EXPECT_EQ(c.num_cached(), 1u);
  EXPECT_THROW(c.column(-1), std::invalid_argument);
  EXPECT_THROW(c.column(solver_.num_dofs()), std::invalid_argument);
}

TEST_F(FemCompliance, BlockIsSymmetricAndMatchesSingleColumns) {
  const auto top = nodes_where(mesh_, [](const Eigen::Vector3d& p) { return p.z() > 0.03 - 1e-9; });
  std::vector<int> s(top.begin(), top.begin() + 10);
  s.push_back(bottom_[2]);  // a fixed node inside S: zero rows and columns
  ComplianceOptions small_blocks;
  small_blocks.block_columns = 7;  // several block solves, the last one partial
  Compliance blocked(solver_, small_blocks);
  const Eigen::MatrixXd lss = blocked.block(s);
  ASSERT_EQ(lss.rows(), 3 * static_cast<Eigen::Index>(s.size()));
  EXPECT_LE((lss - lss.transpose()).cwiseAbs().maxCoeff(), 1e-12 * lss.cwiseAbs().maxCoeff());
  EXPECT_EQ(lss.bottomRows<3>().norm(), 0.0);
  Compliance single(solver_);
  for (std::size_t k = 0; k < s.size(); ++k) {
    for (int a = 0; a < 3; ++a) {
      const Eigen::VectorXd& col = single.column(3 * s[k] + a);
      const Eigen::VectorXd* cached = blocked.find_column(3 * s[k] + a);
      ASSERT_NE(cached, nullptr);
      EXPECT_LE((*cached - col).cwiseAbs().maxCoeff(), 1e-12 * col.cwiseAbs().maxCoeff() + 1e-300);
    }
  }
  // L_SS is positive definite on the free nodes.
  const Eigen::MatrixXd free_block = lss.topLeftCorner(30, 30);
  EXPECT_EQ(Eigen::LLT<Eigen::MatrixXd>(free_block).info(), Eigen::Success);
  // From the cache into a preallocated matrix.
  Eigen::MatrixXd out(lss.rows(), lss.cols());
  const double* data = out.data();
  blocked.block_from_cache(s, out);
  EXPECT_EQ(out.data(), data);
  EXPECT_EQ((out - lss).norm(), 0.0);
  std::vector<int> unknown{top[20]};
  EXPECT_THROW(blocked.block_from_cache(unknown, out), std::logic_error);
  EXPECT_GT(blocked.cache_bytes(), 0u);
  EXPECT_GT(blocked.factor_info().factor_bytes, 0u);
}

TEST_F(FemCompliance, ReferencesStayValidWhileTheCacheGrows) {
  Compliance c(solver_);
  const Eigen::VectorXd* first = &c.column(3 * 70);
  const Eigen::VectorXd copy = *first;
  std::vector<int> many;
  for (int v = 0; v < 60; ++v) {
    many.push_back(3 * (v + 20) + 1);
  }
  c.precompute(many);
  EXPECT_EQ(c.find_column(3 * 70), first);
  EXPECT_EQ((*first - copy).norm(), 0.0);
  c.clear();
  EXPECT_EQ(c.num_cached(), 0u);
  EXPECT_EQ(c.find_column(3 * 70), nullptr);
}

}  // namespace
}  // namespace neurosim::fem
