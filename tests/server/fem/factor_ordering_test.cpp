// The factor's fill-reducing ordering (fem/factor_ordering.hpp, SolverOptions::ordering,
// EquilibriumDefinition::ordering): every ordering gives the same displacements to round-off;
// node-metis keeps each node's three rows together in the permutation and gives a smaller factor
// than AMD on a 3D mesh; the factor cache keys the ordering; bad names and sizes are refused.
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/factor_ordering.hpp"
#include "server/fem/static_solver.hpp"

#include "fem_test_meshes.hpp"
#include "test_support.hpp"

#include <cholmod.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <vector>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

const Material kBrain{1.0e6, 0.45, "brain"};
constexpr FactorOrdering kAll[] = {FactorOrdering::kCholmodDefault, FactorOrdering::kAmd,
                                   FactorOrdering::kMetis, FactorOrdering::kNesdis,
                                   FactorOrdering::kNodeMetis};

mesh::TetMesh cube() { return box_mesh(BoxSpec{9, 8, 10, {0, 0, 0}, {0.1, 0.08, 0.12}, 0.2, 5}); }

std::vector<int> bottom(const mesh::TetMesh& m) {
  return nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
}

SolverOptions with(FactorOrdering o) {
  SolverOptions s;
  s.ordering = o;
  return s;
}

Eigen::VectorXd load(int n) {
  Eigen::VectorXd f(n);
  for (int i = 0; i < n; ++i) f[i] = 0.01 * std::sin(0.37 * i + 0.1);
  return f;
}

TEST(fem_factor_ordering, EveryOrderingGivesTheSameDisplacements) {
  const auto m = cube();
  const StaticSolver reference(m, MaterialMap::uniform(kBrain), bottom(m), with(kAll[0]));
  const Eigen::VectorXd f = load(reference.num_dofs());
  const Eigen::VectorXd u0 = reference.solve(f);
  ASSERT_GT(u0.cwiseAbs().maxCoeff(), 0.0);
  for (FactorOrdering o : kAll) {
    const StaticSolver s(m, MaterialMap::uniform(kBrain), bottom(m), with(o));
    EXPECT_EQ(s.factor_info().ordering.rfind(ordering_name(o), 0), 0u) << ordering_name(o);
    EXPECT_LT(testing::rel_max_diff(s.solve(f), u0), 1e-11) << ordering_name(o);
  }
}

TEST(fem_factor_ordering, NodeMetisKeepsANodesRowsTogetherAndBeatsAmdOnA3dMesh) {
  const auto m = cube();
  const StaticSolver amd(m, MaterialMap::uniform(kBrain), bottom(m), with(FactorOrdering::kAmd));
  const StaticSolver node(m, MaterialMap::uniform(kBrain), bottom(m),
                          with(FactorOrdering::kNodeMetis));
  EXPECT_LT(node.factor_info().factor_nnz, amd.factor_info().factor_nnz);
  // The permutation itself: analyse K_ff directly and look at L->Perm.
  SparseMatrix lower = amd.stiffness().triangularView<Eigen::Lower>();
  std::vector<int> keep;
  for (int d : amd.free_dofs()) keep.push_back(d);
  const int nf = static_cast<int>(keep.size());
  SparseMatrix kff(nf, nf);
  {
    std::vector<Eigen::Triplet<double>> t;
    for (int j = 0; j < nf; ++j)
      for (SparseMatrix::InnerIterator it(lower, keep[j]); it; ++it) {
        const int i = amd.reduced_index()[it.row()];
        if (i >= j) t.emplace_back(i, j, it.value());
      }
    kff.setFromTriplets(t.begin(), t.end());
    kff.makeCompressed();
  }
  std::vector<int> node_of(static_cast<std::size_t>(nf));
  for (int r = 0; r < nf; ++r) node_of[r] = keep[r] / 3;
  cholmod_common c;
  cholmod_start(&c);
  c.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_factor* l = analyze_ordered(kff, FactorOrdering::kNodeMetis, node_of, c);
  ASSERT_NE(l, nullptr);
  const int* perm = static_cast<const int*>(l->Perm);
  // CHOLMOD's postorder may reorder rows within a node's block, never split it: each node's
  // rows are consecutive in the permutation.
  std::vector<int> first(static_cast<std::size_t>(m.num_vertices()), -1), count(first.size(), 0);
  for (int k = 0; k < nf; ++k) {
    const int v = node_of[perm[k]];
    if (first[v] < 0) first[v] = k;
    EXPECT_LT(k - first[v], 3) << "node " << v;
    ++count[v];
  }
  for (std::size_t v = 0; v < count.size(); ++v) EXPECT_TRUE(count[v] == 0 || count[v] == 3);
  cholmod_free_factor(&l, &c);
  cholmod_finish(&c);
}

TEST(fem_factor_ordering, TheEquilibriumSolverAnswersTheSameWithEveryOrdering) {
  const auto m = cube();
  Eigen::VectorXd u0;
  for (FactorOrdering o : kAll) {
    EquilibriumDefinition d;
    d.mesh = &m;
    d.materials = MaterialMap::uniform(kBrain);
    d.tier = Tier::kNonlinear;
    d.fixed_nodes = bottom(m);
    d.ordering = o;
    EquilibriumSolver s(d);
    Eigen::VectorXd f = Eigen::VectorXd::Zero(s.num_dofs());
    for (int v : nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.12 - 1e-9; }))
      f[3 * v + 2] = -0.5;
    const Eigen::VectorXd u = s.solve(f).displacement_m;
    if (u0.size() == 0) u0 = u;
    ASSERT_GT(u0.cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_LT(testing::rel_max_diff(u, u0), 1e-8) << ordering_name(o);
  }
}

TEST(fem_factor_ordering, TheFactorCacheKeysTheOrdering) {
  const auto dir = neurosim::testing::temp_dir("factor_ordering_cache");
  const auto m = cube();
  SolverOptions a = with(FactorOrdering::kCholmodDefault), b = with(FactorOrdering::kNodeMetis);
  a.factor_cache_dir = b.factor_cache_dir = dir.string();
  { const StaticSolver first(m, MaterialMap::uniform(kBrain), bottom(m), a); }
  const StaticSolver other(m, MaterialMap::uniform(kBrain), bottom(m), b);
  EXPECT_FALSE(other.factor_info().from_cache);
  const StaticSolver again(m, MaterialMap::uniform(kBrain), bottom(m), b);
  EXPECT_TRUE(again.factor_info().from_cache);
  std::filesystem::remove_all(dir);
}

TEST(fem_factor_ordering, BadNamesAndSizesAreRefused) {
  for (FactorOrdering o : kAll) EXPECT_EQ(ordering_from_name(ordering_name(o)), o);
  EXPECT_THROW(ordering_from_name("colamd"), std::invalid_argument);
  SparseMatrix lower(3, 3);
  lower.setIdentity();
  lower.makeCompressed();
  cholmod_common c;
  cholmod_start(&c);
  EXPECT_THROW(analyze_ordered(lower, FactorOrdering::kNodeMetis, {0, 0}, c),
               std::invalid_argument);
  cholmod_finish(&c);
}

}  // namespace
}  // namespace neurosim::fem
