// cholmod_threads_follow_omp_num_threads: CHOLMOD (Debian's build) runs its supernodal copies in
// OpenMP regions of 4 threads whatever OMP_NUM_THREADS says; with OMP_NUM_THREADS=1
// (deploy/test's default) and the call, a factorization large enough to enter those regions
// starts no thread.
#include "server/fem/cholmod_threads.hpp"

#include "fem_test_meshes.hpp"
#include "server/fem/static_solver.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::nodes_where;

int threads_of_this_process() {
  int n = 0;
  for ([[maybe_unused]] const auto& task : std::filesystem::directory_iterator("/proc/self/task")) ++n;
  return n;
}

// A 12^3-hexahedra box (6.6k free dofs): large enough for CHOLMOD's parallel regions, which a
// thread that did not make the call then shows (its factorization starts threads: the check on
// the calling thread is not vacuous).
TEST(FemCholmodThreads, CholmodStartsNoThreadWhenOmpNumThreadsIsOne) {
  const char* env = std::getenv("OMP_NUM_THREADS");
  if (!env || std::string(env) != "1") GTEST_SKIP() << "needs OMP_NUM_THREADS=1 (deploy/test sets it)";
  const mesh::TetMesh m = box_mesh({12, 12, 12, {0, 0, 0}, {0.06, 0.06, 0.06}, 0.0, 1});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  ASSERT_TRUE(cholmod_threads_follow_omp_num_threads());
  const int before = threads_of_this_process();
  const StaticSolver solver(m, mats, fixed);
  EXPECT_GT(solver.factor_info().factor_nnz, 0);
  EXPECT_EQ(threads_of_this_process(), before) << "CHOLMOD started threads after the call";
  int other_before = 0, other_after = 0;
  std::thread other([&] {
    other_before = threads_of_this_process();
    const StaticSolver s(m, mats, fixed);
    other_after = threads_of_this_process();
  });
  other.join();
  EXPECT_GT(other_after, other_before)
      << "a thread without the call started none either: this CHOLMOD has no OpenMP regions "
         "this box enters, the check above proves nothing";
}

}  // namespace
}  // namespace neurosim::fem
