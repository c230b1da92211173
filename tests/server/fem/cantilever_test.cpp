// Cantilever under an end load: the tip deflection of the constant-strain tetrahedron mesh
// converges to beam theory (Euler-Bernoulli + Timoshenko shear) as the mesh is refined.
#include "fem_test_meshes.hpp"
#include "server/fem/static_solver.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

struct Row {
  int n;
  std::size_t nodes, tets;
  int dofs;
  double tip_m;
};

TEST(FemCantilever, TipDeflectionConvergesToBeamTheory) {
  const double length = 1.0, h = 0.1;  // m: square section h x h, slenderness 10
  const Material steel_like{1.0e6, 0.3, "beam"};
  const double load = 1.0;                      // N, total, in -z, uniform traction on the tip face
  const double inertia = h * h * h * h / 12.0;  // m^4
  const double area = h * h;
  const double kappa =
      10.0 * (1.0 + steel_like.poisson_ratio) / (12.0 + 11.0 * steel_like.poisson_ratio);
  const double euler_bernoulli =
      load * length * length * length / (3.0 * steel_like.youngs_modulus_pa * inertia);
  const double timoshenko =
      euler_bernoulli + load * length / (kappa * steel_like.shear_modulus_pa() * area);

  std::vector<Row> rows;
  for (int n : {1, 2, 4, 6, 8, 12}) {
    const auto m = box_mesh(BoxSpec{10 * n, n, n, {0, 0, 0}, {length, h, h}});
    const auto clamped = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-12; });
    const StaticSolver solver(m, MaterialMap::uniform(steel_like), clamped);
    // Uniform traction: each tip-face triangle gives a third of its load to each vertex.
    Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
    double tip_area = 0.0;
    for (const auto& tri : m.surface()) {
      const auto& x = m.vertices();
      if (x[tri[0]].x() < length - 1e-12 || x[tri[1]].x() < length - 1e-12 ||
          x[tri[2]].x() < length - 1e-12) {
        continue;
      }
      const double a = 0.5 * (x[tri[1]] - x[tri[0]]).cross(x[tri[2]] - x[tri[0]]).norm();
      tip_area += a;
      for (int v : tri) {
        f[3 * v + 2] -= load / area * a / 3.0;
      }
    }
    ASSERT_NEAR(tip_area, area, 1e-12);
    const Eigen::VectorXd u = solver.solve(f);
    // Work-conjugate tip deflection: f . u / P.
    rows.push_back({n, m.num_vertices(), m.num_tets(), solver.num_free_dofs(), f.dot(u) / load});
  }
  std::printf(
      "\ncantilever L = %.2f m, section %.2f x %.2f m, E = %.3g Pa, nu = %.2f, P = %.1f N\n",
      length, h, h, steel_like.youngs_modulus_pa, steel_like.poisson_ratio, load);
  std::printf("beam theory: Euler-Bernoulli %.6e m, Timoshenko %.6e m\n", euler_bernoulli,
              timoshenko);
  std::printf("%-12s %8s %8s %8s %14s %14s %10s\n", "mesh", "nodes", "tets", "dofs", "tip [m]",
              "Timoshenko [m]", "error");
  double previous_error = 1e300;
  for (const Row& r : rows) {
    const double error = std::abs(r.tip_m - timoshenko) / timoshenko;
    char name[32];
    std::snprintf(name, sizeof(name), "%dx%dx%d", 10 * r.n, r.n, r.n);
    std::printf("%-12s %8zu %8zu %8d %14.6e %14.6e %9.2f%%\n", name, r.nodes, r.tets, r.dofs,
                r.tip_m, timoshenko, 100.0 * error);
    EXPECT_LT(r.tip_m, timoshenko * 1.01) << "linear tetrahedra are too stiff, never too soft";
    EXPECT_LT(error, previous_error) << "error must decrease with refinement";
    previous_error = error;
  }
  EXPECT_LT(previous_error, 0.05) << "finest mesh within 5 % of beam theory";
  // Richardson extrapolation of the two finest meshes (error ~ h^2): the limit of the
  // sequence, which 3D elasticity puts within about 1 % of Timoshenko (clamp, load spread).
  const Row& a = rows[rows.size() - 2];
  const Row& b = rows.back();
  const double ratio2 = static_cast<double>(b.n * b.n) / static_cast<double>(a.n * a.n);
  const double extrapolated = (ratio2 * b.tip_m - a.tip_m) / (ratio2 - 1.0);
  const double extrapolated_error = std::abs(extrapolated - timoshenko) / timoshenko;
  std::printf("Richardson (h^2) limit %.6e m: %.2f%% from Timoshenko\n", extrapolated,
              100.0 * extrapolated_error);
  EXPECT_LT(extrapolated_error, 0.02);
}

}  // namespace
}  // namespace neurosim::fem
