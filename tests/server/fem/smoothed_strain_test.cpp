// The selective smoothed tetrahedron's smoothing cells (smoothed_strain.hpp) and its NONLINEAR
// tier under large local deformation: the cells tile the volume and reproduce an affine field;
// the tangent is the derivative of the internal forces (central differences) at a point-loaded
// equilibrium the element barrier holds and beyond it where tetrahedra under the load are
// inverted; Newton converges quadratically on a
// pressed patch and under a point load (iterations per increment, residual contraction), with
// the exact (not the projected) tangent.
#include "server/fem/smoothed_strain.hpp"

#include "elastic_forces_checks.hpp"
#include "fem_test_meshes.hpp"
#include "server/fem/elastic_forces.hpp"
#include "server/fem/equilibrium_solver.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::nodes_where;

Material smoothed(double nu) {
  Material m{3000.0, nu, "brain"};
  m.element = Element::kSmoothedTet;
  return m;
}

// A 60 mm block of 6 x 6 x 6 jittered hexahedra (10 mm cells, as the bundled brain's 7 mm),
// base fixed.
struct Block {
  mesh::TetMesh mesh = box_mesh({6, 6, 6, {0, 0, 0}, {0.06, 0.06, 0.06}, 0.2, 3});
  std::vector<int> fixed =
      nodes_where(mesh, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  int top_centre() const {
    const std::vector<int> v = nodes_where(mesh, [](const Eigen::Vector3d& p) {
      return (p - Eigen::Vector3d(0.03, 0.03, 0.06)).norm() < 1e-9;
    });
    return v.at(0);
  }
};

void print_increments(const std::string& what, const EquilibriumResult& r) {
  for (const NewtonIncrement& inc : r.increments) {
    std::printf("%s, load factor %.3f (%d projected):", what.c_str(), inc.load_factor,
                inc.projected_iterations);
    for (double x : inc.residual_n) std::printf(" %.1e", x);
    std::printf(" N\n");
  }
}

int iterations(const EquilibriumResult& r) {
  int n = 0;
  for (const NewtonIncrement& inc : r.increments) n += static_cast<int>(inc.residual_n.size()) - 1;
  return n;
}

// Newton converged quadratically in every increment: no cutback, at most 8 iterations (a
// linear rate of 1/2 would need ~35 for the 1e-10 tolerance), the projected tangent at most in
// the first two (a press's increment starts with only the pressed nodes moved, compressing the
// elements under them: the exact tangent there is indefinite for every element, linear-tet
// included), and the order of convergence from the last three residuals above round-off
// (1e-13 of the first), log(r3 / r2) / log(r2 / r1), at least 1.5.
void expect_quadratic(const EquilibriumResult& r, const std::string& what) {
  for (const NewtonIncrement& inc : r.increments) {
    const std::string at = what + " load factor " + std::to_string(inc.load_factor);
    EXPECT_EQ(inc.cutbacks, 0) << at;
    EXPECT_LE(inc.residual_n.size() - 1, 8u) << at;
    EXPECT_LE(inc.projected_iterations, 2) << at;
    std::vector<double> above;
    for (double x : inc.residual_n) {
      if (x > 1e-13 * inc.residual_n.front()) above.push_back(x);
    }
    ASSERT_GE(above.size(), 3u) << at;
    const std::size_t n = above.size();
    const double order = std::log(above[n - 1] / above[n - 2]) / std::log(above[n - 2] / above[n - 3]);
    EXPECT_GE(order, 1.5) << at;
  }
}

TEST(FemSmoothedStrain, CellsTileTheVolumeAndReproduceAnAffineField) {
  const Block b;
  const mesh::TetMesh& m = b.mesh;
  const MaterialMap mats = MaterialMap::uniform(smoothed(0.49));
  const SmoothedStrain cells(m, mats, StiffnessAssembler(m, Element::kSmoothedTet).pattern());
  double volume = 0.0;
  for (int c = 0; c < cells.num_cells(); ++c) volume += cells.volume_m3(c);
  EXPECT_NEAR(volume, 0.06 * 0.06 * 0.06, 1e-12);
  Eigen::Matrix3d h;
  h << 0.2, -0.1, 0.05, 0.03, -0.15, 0.1, -0.07, 0.02, 0.3;
  Eigen::VectorXd u(3 * m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) u.segment<3>(3 * v) = h * m.vertices()[v];
  double worst = 0.0;
  for (int c = 0; c < cells.num_cells(); ++c) {
    worst = std::max(worst, (cells.displacement_gradient(c, u) - h).cwiseAbs().maxCoeff());
  }
  EXPECT_LT(worst, 1e-13);
}

// The tangent is the derivative of the forces (every dof of the loaded node and its neighbours,
// and the shared check's dofs) at u.
void expect_tangent_is_derivative_near(const ElasticForces& forces, const Eigen::VectorXd& u,
                                       int node, const std::string& what) {
  SparseMatrix k;
  forces.tangent(u, false, k);
  const Eigen::MatrixXd kd(k);
  EXPECT_LT((kd - kd.transpose()).cwiseAbs().maxCoeff(), 1e-12 * kd.cwiseAbs().maxCoeff()) << what;
  testing::expect_tangent_is_force_derivative(forces, u, kd, "NONLINEAR, " + what);
  // The loaded node's neighbourhood (its nonzero column entries): where the elements invert.
  std::vector<int> near;
  for (SparseMatrix::InnerIterator it(k, 3 * node + 2); it; ++it) near.push_back(static_cast<int>(it.row()));
  const double h = 1e-8;
  double worst = 0.0;
  for (int dof : near) {
    Eigen::VectorXd up = u, um = u, fp, fm;
    up[dof] += h;
    um[dof] -= h;
    forces.internal_force(up, fp);
    forces.internal_force(um, fm);
    const Eigen::VectorXd fd = (fp - fm) / (2.0 * h);
    worst = std::max(worst, (fd - kd.col(dof)).cwiseAbs().maxCoeff() /
                                kd.col(dof).cwiseAbs().maxCoeff());
  }
  std::printf("%s: tangent vs central differences, %zu dofs around the loaded node: worst %.2e\n",
              what.c_str(), near.size(), worst);
  EXPECT_LT(worst, 1e-6) << what;
}

// The point-loaded block at nu = 0.49: 0.45 N on the top centre node sinks it about 20 mm into
// the 60 mm block. The element barrier (element_barrier.hpp) holds the tetrahedra under it
// (without it they inverted and the node sank 26 mm): at the equilibrium it is active and
// nothing is inverted, and Newton reached it quadratically. The tangent is the derivative of
// the forces there and at the same field 1.6 times deeper, where tetrahedra under the node are
// inverted (the barrier's cofactor terms through J < 0; the smoothing cells are not inverted).
TEST(FemSmoothedStrain, NonlinearTangentIsTheForceDerivativeWithInvertedElements) {
  const Block b;
  const int top = b.top_centre();
  const MaterialMap mats = MaterialMap::uniform(smoothed(0.49));
  EquilibriumSolver solver({&b.mesh, mats, Tier::kNonlinear, b.fixed, {}, {}});
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(b.mesh.num_vertices()));
  f[3 * top + 2] = -0.45;
  const EquilibriumResult r = solver.solve(f);
  print_increments("point load 0.45 N", r);
  const ElasticForces& forces = solver.forces();
  const Eigen::VectorXd& u = r.displacement_m;
  ElasticForcesReport at_rest_load;
  forces.energy(u, &at_rest_load);
  std::printf("point load 0.45 N: top node %.2f mm down, %d inverted, %d held by the barrier\n",
              -1e3 * u[3 * top + 2], at_rest_load.inverted_elements, at_rest_load.barrier_elements);
  EXPECT_EQ(at_rest_load.inverted_elements, 0);
  EXPECT_GT(at_rest_load.barrier_elements, 0);
  EXPECT_GT(-u[3 * top + 2], 0.015);
  EXPECT_LT(-u[3 * top + 2], 0.025);
  expect_quadratic(r, "point load");
  expect_tangent_is_derivative_near(forces, u, top, "point-loaded equilibrium");

  const Eigen::VectorXd deeper = 1.6 * u;
  ElasticForcesReport over;
  forces.energy(deeper, &over);
  std::printf("1.6 x deeper: top node %.2f mm down, %d inverted, %d held by the barrier\n",
              -1e3 * deeper[3 * top + 2], over.inverted_elements, over.barrier_elements);
  EXPECT_GT(over.inverted_elements, 0);
  expect_tangent_is_derivative_near(forces, deeper, top, "1.6 x deeper, inverted");
}

// A 20 x 20 mm patch on top pressed 8 mm (the bundled brain's press depths), nu = 0.49 and
// 0.499: quadratic in every increment.
TEST(FemSmoothedStrain, NewtonConvergesQuadraticallyOnAPress) {
  const Block b;
  const std::vector<int> patch = nodes_where(b.mesh, [](const Eigen::Vector3d& p) {
    return p.z() > 0.06 - 1e-9 && std::abs(p.x() - 0.03) < 0.0101 && std::abs(p.y() - 0.03) < 0.0101;
  });
  ASSERT_EQ(patch.size(), 9u);
  for (double nu : {0.49, 0.499}) {
    const std::string what = "press 8 mm, nu " + std::to_string(nu);
    EquilibriumSolver solver({&b.mesh, MaterialMap::uniform(smoothed(nu)), Tier::kNonlinear, b.fixed,
                              {{patch, Eigen::Vector3d(0, 0, -0.008), kAllComponents}}, {}});
    const EquilibriumResult r = solver.solve({});
    print_increments(what, r);
    double force = 0.0;
    for (int v : patch) force += r.reaction_n[3 * v + 2];
    std::printf("%s: patch force %.4f N\n", what.c_str(), -force);
    EXPECT_LT(force, 0.0) << what;
    expect_quadratic(r, what);
    // linear-tet on the same press: the same solver, the reference iteration count.
    Material linear = smoothed(nu);
    linear.element = Element::kLinearTet;
    EquilibriumSolver reference({&b.mesh, MaterialMap::uniform(linear), Tier::kNonlinear, b.fixed,
                                 {{patch, Eigen::Vector3d(0, 0, -0.008), kAllComponents}}, {}});
    const int linear_iterations = iterations(reference.solve({}));
    std::printf("%s: %d Newton iterations (linear-tet %d)\n", what.c_str(), iterations(r),
                linear_iterations);
    EXPECT_LE(iterations(r), linear_iterations + 2) << what;
  }
}

}  // namespace
}  // namespace neurosim::fem
