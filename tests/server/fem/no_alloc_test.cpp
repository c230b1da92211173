// Per-step paths allocate nothing once warmed up (Model vs State): StaticSolver::solve(f, u)
// with a sized u, Compliance::find_column and block_from_cache into a sized matrix; the
// locking-free elements' energy, forces and tangent with a warmed ElasticForces::Workspace.
// Counts every malloc/calloc/realloc in the process while the steps run.
#include "fem_test_meshes.hpp"
#include "server/fem/compliance.hpp"
#include "server/fem/elastic_forces.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>

namespace {
std::atomic<bool> g_counting{false};
std::atomic<long> g_allocations{0};
void note() {
  if (g_counting.load(std::memory_order_relaxed)) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
  }
}
}  // namespace

// Interpose glibc's allocator for the whole process: Eigen, CHOLMOD, OpenBLAS and operator new
// all end up here.
extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* malloc(std::size_t n) {
  note();
  return __libc_malloc(n);
}
void* calloc(std::size_t n, std::size_t s) {
  note();
  return __libc_calloc(n, s);
}
void* realloc(void* p, std::size_t n) {
  note();
  return __libc_realloc(p, n);
}
}

namespace neurosim::fem {
namespace {

TEST(FemNoAlloc, SolveAndCacheLookupsDoNotAllocate) {
  const auto m = testing::box_mesh(testing::BoxSpec{6, 6, 6, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 3});
  const auto bottom =
      testing::nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const StaticSolver solver(m, MaterialMap::uniform({1e6, 0.4, "brain"}), bottom);
  Compliance compliance(solver);
  const std::vector<int> s{300, 301, 302, 310, 320};
  compliance.precompute_nodes(s);
  Eigen::MatrixXd block(3 * s.size(), 3 * s.size());
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs()), u(solver.num_dofs());
  solver.solve(f, u);  // warm-up: CHOLMOD workspace is allocated here

  g_allocations = 0;
  g_counting = true;
  double sum = 0.0;
  for (int step = 0; step < 20; ++step) {
    f[3 * 330 + 2] = -0.01 * step;
    solver.solve(f, u);
    sum += u[3 * 330 + 2];
    sum += (*compliance.find_column(3 * 301 + 1))[3 * 302];
    compliance.block_from_cache(s, block);
    sum += block(0, 0);
  }
  g_counting = false;
  EXPECT_EQ(g_allocations.load(), 0) << "allocations in per-step paths";
  EXPECT_TRUE(std::isfinite(sum));
  // The counter works: a cache miss allocates.
  g_counting = true;
  compliance.column(3 * 200);
  g_counting = false;
  EXPECT_GT(g_allocations.load(), 0);
}

TEST(FemNoAlloc, LockingFreeElementEvaluationsDoNotAllocate) {
  const auto m = testing::box_mesh(testing::BoxSpec{3, 3, 3, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 3});
  for (Element element : {Element::kAnpTet, Element::kSmoothedTet}) {
    Material mat{3000.0, 0.49, "brain"};
    mat.element = element;
    const ElasticForces forces(m, MaterialMap::uniform(mat), Tier::kNonlinear);
    Eigen::VectorXd u = Eigen::VectorXd::Constant(forces.num_dofs(), 1e-3), f(forces.num_dofs());
    SparseMatrix k;
    ElasticForces::Workspace ws;
    ElasticForcesReport report;
    forces.tangent(u, false, k, &report, &ws);  // warm-up: the workspace and k's pattern
    forces.internal_force(u, f, &report, &ws);
    g_allocations = 0;
    g_counting = true;
    double sum = 0.0;
    for (int step = 0; step < 5; ++step) {
      u[7] = 1e-3 * step;
      sum += forces.energy(u, &report, &ws);
      forces.internal_force(u, f, &report, &ws);
      forces.tangent(u, step % 2 == 1, k, &report, &ws);
      sum += f[7] + k.valuePtr()[0];
    }
    g_counting = false;
    EXPECT_EQ(g_allocations.load(), 0) << element_name(element);
    EXPECT_TRUE(std::isfinite(sum));
    // The counter sees this path: without a workspace each evaluation allocates its own.
    g_counting = true;
    forces.internal_force(u, f, &report);
    g_counting = false;
    EXPECT_GT(g_allocations.load(), 0) << element_name(element);
  }
}

}  // namespace
}  // namespace neurosim::fem
