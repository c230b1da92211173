// Against CalculiX on the paper's cube (Table 2a: 1812 vertices, CGAL Mesh_3): bottom fixed,
// the tool footprint on the right face pushed 5 mm towards -x, a body-force-like load on all
// nodes; displacements and reactions agree to 1e-6 relative.
#include "fem_test_meshes.hpp"
#include "server/fem/calculix.hpp"
#include "server/fem/static_solver.hpp"
#include "server/mesh/generate.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>

namespace neurosim::fem {
namespace {

TEST(FemCalculixPaperCube, MatchesCalculix) {
  mesh::MeshingOptions o;
  o.target_vertices = 1812;
  o.seed = 1;
  const double e = 0.1;  // m
  const mesh::TetMesh m = mesh::generate_box({0, 0, 0}, {e, e, e}, o).mesh;
  const MaterialMap mats = MaterialMap::uniform({1.0e6, 0.4, "paper_cube"});
  CalculixLoads loads;
  const double tol = 1e-9;
  loads.fixed_nodes =
      testing::nodes_where(m, [&](const Eigen::Vector3d& p) { return p.z() < tol; });
  loads.prescribed_nodes = testing::nodes_where(m, [&](const Eigen::Vector3d& p) {
    return p.x() > e - tol && (p - Eigen::Vector3d(e, 0.5 * e, 0.5 * e)).norm() < 0.012 &&
           p.z() > tol;
  });
  ASSERT_FALSE(loads.prescribed_nodes.empty());
  loads.prescribed_displacements_m = Eigen::VectorXd::Zero(3 * loads.prescribed_nodes.size());
  for (std::size_t k = 0; k < loads.prescribed_nodes.size(); ++k) {
    loads.prescribed_displacements_m[3 * k] = -5e-3;
  }
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    loads.forces_n[3 * v + 2] = -1e-3;  // N per node
  }

  const StaticSolver solver(m, mats, loads.fixed_nodes);
  const auto ours = solver.solve_prescribed(loads.prescribed_nodes,
                                            loads.prescribed_displacements_m, loads.forces_n);
  const auto dir = neurosim::testing::temp_dir("ccx_paper_cube");
  const CalculixResult ccx = run_calculix(dir, "paper_cube", m, mats, loads, {"ccx", 240.0});
  const double du = testing::rel_max_diff(ours.displacement_m, ccx.displacement_m);
  Eigen::VectorXd rf = Eigen::VectorXd::Zero(ours.reaction_n.size());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    if (ccx.has_reaction[v]) {
      // ccx's RF is K u at the node: loads applied on constrained dofs are not subtracted.
      rf.segment<3>(3 * v) = ours.reaction_n.segment<3>(3 * v) + loads.forces_n.segment<3>(3 * v);
    }
  }
  const double drf = testing::rel_max_diff(rf, ccx.reaction_n);
  std::printf(
      "paper cube: %zu vertices, %zu tets, %zu fixed, %zu pushed; max|u| %.4e m; u rel diff %.3e, "
      "RF rel diff "
      "%.3e; factor %.1f ms\n",
      m.num_vertices(), m.num_tets(), loads.fixed_nodes.size(), loads.prescribed_nodes.size(),
      ccx.displacement_m.cwiseAbs().maxCoeff(), du, drf, 1e3 * solver.factor_info().factorize_s);
  EXPECT_LE(du, 1e-6);
  EXPECT_LE(drf, 1e-6);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::fem
