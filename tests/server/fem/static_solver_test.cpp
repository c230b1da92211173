// Static solver: patch test, equilibrium of reactions, prescribed displacements through
// elimination and through the Schur complement, prescribed by component (only some of x, y, z
// held), singular and non-finite input.
#include "server/fem/static_solver.hpp"
#include "fem_test_meshes.hpp"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <thread>
#include <limits>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

const Material kBrain{1.0e6, 0.4, "brain"};

// A jittered 0.1 m brain cube of 4 x 4 x 4 hexahedra (seed `seed`) clamped at its bottom,
// solved with the residual check at 1e-10, and the same force (N) on every top node.
struct ClampedCube {
  explicit ClampedCube(unsigned seed)
      : mesh(box_mesh(BoxSpec{4, 4, 4, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, seed})),
        bottom(nodes_where(mesh, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; })),
        top(nodes_where(mesh, [](const Eigen::Vector3d& p) { return p.z() > 0.1 - 1e-9; })),
        solver(mesh, MaterialMap::uniform(kBrain), bottom, options()) {}
  Eigen::VectorXd top_load(const Eigen::Vector3d& per_node_n) const {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
    for (int v : top) f.segment<3>(3 * v) = per_node_n;
    return f;
  }
  static SolverOptions options() {
    SolverOptions opt;
    opt.check_residual = true;
    opt.residual_tolerance = 1e-10;
    return opt;
  }
  mesh::TetMesh mesh;
  std::vector<int> bottom, top;
  StaticSolver solver;
};

// Linear field u = A x + c (m).
Eigen::VectorXd linear_field(const mesh::TetMesh& m) {
  Eigen::Matrix3d a;
  a << 1e-3, -2e-3, 0.5e-3, 0.7e-3, 1.5e-3, -1e-3, 2e-3, 0.3e-3, -0.8e-3;
  const Eigen::Vector3d c(1e-4, -2e-4, 3e-4);
  Eigen::VectorXd u(3 * m.num_vertices());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    u.segment<3>(3 * v) = a * m.vertices()[v] + c;
  }
  return u;
}

Eigen::VectorXd values_at(const Eigen::VectorXd& u, const std::vector<int>& nodes) {
  Eigen::VectorXd out(3 * nodes.size());
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    out.segment<3>(3 * k) = u.segment<3>(3 * nodes[k]);
  }
  return out;
}

TEST(FemStaticSolver, PatchTestIrregularMesh) {
  // Irregular mesh: interior nodes jittered by up to 30 % of a cell.
  const auto m = box_mesh(BoxSpec{5, 4, 4, {0, 0, 0}, {0.05, 0.04, 0.04}, 0.3, 11});
  const Eigen::VectorXd exact = linear_field(m);
  const std::vector<int>& boundary = m.surface_vertices();
  ASSERT_LT(boundary.size(), m.num_vertices());
  // (a) Boundary nodes eliminated (fixed in the factor), values imposed per solve.
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), boundary);
  const auto sol = solver.solve_prescribed(boundary, values_at(exact, boundary));
  const double err = testing::rel_max_diff(sol.displacement_m, exact);
  std::printf("patch test (eliminated boundary): max rel error %.3e\n", err);
  EXPECT_LE(err, 1e-12);
  // Interior nodes carry no reaction: a linear field is in equilibrium without body forces.
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    if (!std::binary_search(boundary.begin(), boundary.end(), static_cast<int>(v))) {
      EXPECT_EQ(sol.reaction_n.segment<3>(3 * v).norm(), 0.0);
    }
  }

  // (b) Only the x = 0 face eliminated; the rest of the boundary prescribed through the Schur
  // complement of the factor (no refactorization).
  const auto face = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  const StaticSolver partial(m, MaterialMap::uniform(kBrain), face);
  const auto sol_b = partial.solve_prescribed(boundary, values_at(exact, boundary));
  const double err_b = testing::rel_max_diff(sol_b.displacement_m, exact);
  std::printf("patch test (Schur-complement boundary): max rel error %.3e\n", err_b);
  EXPECT_LE(err_b, 1e-12);
  EXPECT_LE((sol_b.reaction_n - sol.reaction_n).cwiseAbs().maxCoeff(),
            1e-9 * sol.reaction_n.cwiseAbs().maxCoeff());
}

TEST(FemStaticSolver, ReactionsBalanceLoadsAndResidualIsSmall) {
  const ClampedCube cube(3);
  const auto& [m, bottom, top, solver] = cube;
  const Eigen::VectorXd f = cube.top_load(Eigen::Vector3d(0.2, -0.1, -1.0));
  const auto sol = solver.solve_prescribed({}, Eigen::VectorXd(), f);
  const Eigen::VectorXd u = solver.solve(f);
  EXPECT_LE((u - sol.displacement_m).cwiseAbs().maxCoeff(), 1e-14 * u.cwiseAbs().maxCoeff());
  for (int v : bottom) {
    EXPECT_EQ(u.segment<3>(3 * v).norm(), 0.0);
  }
  // Force and moment balance: sum(f) + sum(r) = 0, sum(x × (f + r)) = 0.
  Eigen::Vector3d force = Eigen::Vector3d::Zero(), moment = Eigen::Vector3d::Zero();
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    const Eigen::Vector3d t = f.segment<3>(3 * v) + sol.reaction_n.segment<3>(3 * v);
    force += t;
    moment += m.vertices()[v].cross(t);
  }
  const double total = f.cwiseAbs().sum();
  EXPECT_LE(force.norm(), 1e-10 * total);
  EXPECT_LE(moment.norm(), 1e-10 * total * 0.1);
  // The top moves down under a downward load.
  EXPECT_LT(u[3 * top[0] + 2], 0.0);
}

TEST(FemStaticSolver, ConditionEstimateMatchesDenseEigenvalues) {
  const auto m = box_mesh(BoxSpec{3, 2, 2, {0, 0, 0}, {0.03, 0.02, 0.02}, 0.2, 4});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), fixed);
  const ConditionEstimate est = solver.estimate_condition(2000, 1e-12);
  Eigen::MatrixXd kff(solver.num_free_dofs(), solver.num_free_dofs());
  const Eigen::MatrixXd k(solver.stiffness());
  for (int i = 0; i < kff.rows(); ++i) {
    for (int j = 0; j < kff.cols(); ++j) {
      kff(i, j) = k(solver.free_dofs()[i], solver.free_dofs()[j]);
    }
  }
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(kff).eigenvalues();
  std::printf(
      "lambda_max %.6e (dense %.6e), lambda_min %.6e (dense %.6e), cond %.3e, cholmod rcond %.3e\n",
      est.lambda_max, ev(ev.size() - 1), est.lambda_min, ev(0), est.condition, est.rcond_cholmod);
  EXPECT_NEAR(est.lambda_max, ev(ev.size() - 1), 1e-3 * ev(ev.size() - 1));
  EXPECT_NEAR(est.lambda_min, ev(0), 1e-3 * ev(0));
  const FactorInfo& info = solver.factor_info();
  EXPECT_TRUE(info.supernodal);
  EXPECT_GT(info.factor_nnz, 0);
  EXPECT_GE(info.factor_bytes, static_cast<std::size_t>(info.factor_nnz) * sizeof(double));
}

void expect_message(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    FAIL() << "no exception; expected one mentioning '" << needle << "'";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(FemStaticSolver, InsufficientFixedNodesAreReported) {
  const auto m = box_mesh(BoxSpec{3, 3, 3});
  const MaterialMap mat = MaterialMap::uniform(kBrain);
  expect_message([&] { StaticSolver(m, mat, {}); }, "no fixed node");
  expect_message([&] { StaticSolver(m, mat, {5}); }, "only 1 fixed node");
  // Nodes 0, 1, 2, 3 lie on the line y = z = 0.
  expect_message([&] { StaticSolver(m, mat, {0, 1, 2, 3}); }, "collinear");
  expect_message([&] { StaticSolver(m, mat, {0, 1, 1000}); }, "fixed node 1000 out of range");
  // Without the geometric check, CHOLMOD's factor is what catches it.
  SolverOptions no_check;
  no_check.check_rigid_modes = false;
  expect_message([&] { StaticSolver(m, mat, {}, no_check); }, "singular");
  // Three non-collinear nodes are enough.
  EXPECT_NO_THROW(StaticSolver(m, mat, {0, 3, 12}));
}

// The factor's size is known from the symbolic analysis: a limit below it refuses the mesh
// before the numeric factorization, with the estimate, which is what the factor then holds.
TEST(FemStaticSolver, FactorLargerThanTheMemoryLimitIsRefusedWithTheEstimate) {
  const mesh::TetMesh m = box_mesh({6, 6, 6, {0, 0, 0}, {0.06, 0.06, 0.06}, 0.0, 1});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const MaterialMap mats = MaterialMap::uniform({3000.0, 0.45, "brain"});
  const StaticSolver ok(m, mats, fixed);  // the default limit: the machine's available memory
  const double bytes = static_cast<double>(ok.factor_info().factor_bytes);
  ASSERT_GT(bytes, 0.0);
  SolverOptions tight;
  tight.max_factor_bytes = 0.5 * bytes;
  try {
    StaticSolver refused(m, mats, fixed, tight);
    FAIL() << "a factor of " << bytes << " bytes was not refused at a limit of half of it";
  } catch (const FactorTooLarge& e) {
    EXPECT_DOUBLE_EQ(e.needed_bytes, bytes);
    EXPECT_DOUBLE_EQ(e.available_bytes, 0.5 * bytes);
    EXPECT_NE(std::string(e.what()).find("MiB"), std::string::npos) << e.what();
  }
  tight.max_factor_bytes = bytes;  // exactly enough
  EXPECT_NO_THROW(StaticSolver(m, mats, fixed, tight));
}

TEST(FemStaticSolver, NonFiniteInputIsRefused) {
  const auto m = box_mesh(BoxSpec{2, 2, 2});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const double nan = std::nan(""), inf = std::numeric_limits<double>::infinity();
  expect_message([&] { StaticSolver(m, MaterialMap::uniform({nan, 0.3, "gel"}), fixed); }, "gel");
  expect_message([&] { StaticSolver(m, MaterialMap::uniform({1e6, inf, "gel"}), fixed); }, "gel");
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), fixed);
  for (double bad : {nan, inf, -inf}) {
    Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
    f[3 * 20 + 1] = bad;
    expect_message([&] { solver.solve(f); }, "node 20 axis 1");
    expect_message([&] { solver.solve_prescribed({}, Eigen::VectorXd(), f); }, "node 20 axis 1");
    Eigen::VectorXd d = Eigen::VectorXd::Zero(3);
    d[2] = bad;
    expect_message([&] { solver.solve_prescribed({22}, d); }, "node 22 axis 2");
    expect_message([&] { solver.solve_prescribed({fixed[0]}, d); }, "non-finite displacement");
  }
  expect_message([&] { solver.solve(Eigen::VectorXd::Zero(5)); }, "expected 3N");
  expect_message([&] { solver.solve_prescribed({1, 1}, Eigen::VectorXd::Zero(6)); }, "given twice");
  // Non-finite coordinates never reach the solver: the mesh refuses them.
  std::vector<mesh::Vec3> x{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, nan}};
  EXPECT_THROW(mesh::TetMesh::build(x, {{0, 1, 2, 3}}), std::invalid_argument);
}

TEST(FemStaticSolver, PrescribedFreeNodesMatchEliminatedOnes) {
  const auto m = box_mesh(BoxSpec{4, 3, 3, {0, 0, 0}, {0.04, 0.03, 0.03}, 0.2, 9});
  const auto left = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  const auto right = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() > 0.04 - 1e-9; });
  Eigen::VectorXd d(3 * right.size());
  for (std::size_t k = 0; k < right.size(); ++k) {
    d.segment<3>(3 * k) = Eigen::Vector3d(1e-3, 2e-4, -5e-4);
  }
  Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * m.num_vertices());
  f[3 * 30 + 2] = -0.5;
  // Right face eliminated in the factor vs imposed through the Schur complement.
  std::vector<int> both = left;
  both.insert(both.end(), right.begin(), right.end());
  const StaticSolver eliminated(m, MaterialMap::uniform(kBrain), both);
  const StaticSolver schur(m, MaterialMap::uniform(kBrain), left);
  const auto a = eliminated.solve_prescribed(right, d, f);
  const auto b = schur.solve_prescribed(right, d, f);
  EXPECT_LE(testing::rel_max_diff(b.displacement_m, a.displacement_m), 1e-10);
  EXPECT_LE(testing::rel_max_diff(b.reaction_n, a.reaction_n), 1e-8);
  for (int v : right) {
    EXPECT_LE((b.displacement_m.segment<3>(3 * v) - d.segment<3>(0)).norm(), 1e-15);
  }
}

// A block fixed at its bottom, its top pressed down by prescribing only uz: ux, uy at the top
// are free unknowns (the top spreads by Poisson expansion), with zero reaction there.
TEST(FemStaticSolver, PrescribedOnlySomeComponentsLeavesTheOthersFree) {
  const auto m = box_mesh(BoxSpec{5, 5, 4, {0, 0, 0}, {0.05, 0.05, 0.04}, 0.2, 21});
  const auto bottom = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const auto top = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.04 - 1e-9; });
  SolverOptions opt;
  opt.check_residual = true;
  opt.residual_tolerance = 1e-9;
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), bottom, opt);
  const PrescribedDofs press{top, {0.0, 0.0, -1e-3}, parse_components("z")};
  const auto sol = solver.solve_prescribed_dofs({press});
  const Eigen::VectorXd residual = solver.stiffness() * sol.displacement_m;  // K u - f, f = 0
  double max_reaction = 0.0, max_free_residual = 0.0, max_lateral = 0.0;
  Eigen::Vector3d top_force = Eigen::Vector3d::Zero(), bottom_force = Eigen::Vector3d::Zero();
  for (int v : top) {
    EXPECT_EQ(sol.displacement_m[3 * v + 2], -1e-3);
    max_lateral = std::max(max_lateral, sol.displacement_m.segment<2>(3 * v).cwiseAbs().maxCoeff());
    // Reported: the z reaction only; x, y are free (exactly zero reported, round-off in K u).
    EXPECT_EQ(sol.reaction_n[3 * v], 0.0);
    EXPECT_EQ(sol.reaction_n[3 * v + 1], 0.0);
    EXPECT_EQ(sol.reaction_n[3 * v + 2], residual[3 * v + 2]);
    max_reaction = std::max(max_reaction, std::abs(residual[3 * v + 2]));
    max_free_residual =
        std::max(max_free_residual, residual.segment<2>(3 * v).cwiseAbs().maxCoeff());
    top_force += sol.reaction_n.segment<3>(3 * v);
  }
  for (int v : bottom) {
    EXPECT_EQ(sol.displacement_m.segment<3>(3 * v).norm(), 0.0);
    bottom_force += sol.reaction_n.segment<3>(3 * v);
  }
  std::printf(
      "uz-only press: max lateral |u| at top %.3e m, max |Kz u| %.3e N, max free-component "
      "|K u| %.3e N, top force (%.4e %.4e %.4e) N\n",
      max_lateral, max_reaction, max_free_residual, top_force.x(), top_force.y(), top_force.z());
  // Not clamped: nu = 0.4 under ~2.5 % compression spreads the top by ~1e-4 m at its edges.
  EXPECT_GT(max_lateral, 1e-5);
  EXPECT_LE(max_free_residual, 1e-10 * max_reaction);
  // Pressing down needs a downward force on the top; the bottom pushes back.
  EXPECT_LT(top_force.z(), 0.0);
  EXPECT_LE((top_force + bottom_force).norm(), 1e-10 * std::abs(top_force.z()));
  // No lateral force at the top at all: x, y there carry no constraint.
  EXPECT_EQ(top_force.head<2>().norm(), 0.0);

  // Clamping all three components is a different (stiffer) problem.
  const auto clamped = solver.solve_prescribed_dofs({{top, {0.0, 0.0, -1e-3}}});
  for (int v : top) {
    EXPECT_EQ(clamped.displacement_m.segment<2>(3 * v).norm(), 0.0);
  }
  double clamped_z = 0.0;
  for (int v : top) {
    clamped_z += clamped.reaction_n[3 * v + 2];
  }
  EXPECT_LT(clamped_z, top_force.z());  // more force to press a clamped top as far

  // The per-dof form gives the same answer.
  std::vector<int> dofs;
  for (int v : top) {
    dofs.push_back(3 * v + 2);
  }
  const auto per_dof =
      solver.solve_prescribed_per_dof(dofs, Eigen::VectorXd::Constant(dofs.size(), -1e-3));
  EXPECT_EQ((per_dof.displacement_m - sol.displacement_m).cwiseAbs().maxCoeff(), 0.0);
}

TEST(FemStaticSolver, AllComponentsDefaultMatchesNodeForm) {
  const auto m = box_mesh(BoxSpec{4, 3, 3, {0, 0, 0}, {0.04, 0.03, 0.03}, 0.2, 9});
  const auto left = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-9; });
  const auto right = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() > 0.04 - 1e-9; });
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), left);
  const Eigen::Vector3d d(1e-3, 2e-4, -5e-4);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
  f[3 * 30 + 2] = -0.5;
  Eigen::VectorXd values(3 * right.size());
  for (std::size_t k = 0; k < right.size(); ++k) {
    values.segment<3>(3 * k) = d;
  }
  const auto a = solver.solve_prescribed(right, values, f);
  PrescribedDofs all;  // components default: x, y, z
  all.nodes = right;
  all.displacement_m = d;
  const auto b = solver.solve_prescribed_dofs({all}, f);
  const auto c = solver.solve_prescribed_dofs({{right, d, parse_components("zyx")}}, f);
  EXPECT_EQ((a.displacement_m - b.displacement_m).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((a.reaction_n - b.reaction_n).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ((a.displacement_m - c.displacement_m).cwiseAbs().maxCoeff(), 0.0);
}

TEST(FemStaticSolver, ConflictingPrescribedDofsAreRefusedNamingTheNode) {
  const auto m = box_mesh(BoxSpec{2, 2, 2});
  const auto fixed = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  const StaticSolver solver(m, MaterialMap::uniform(kBrain), fixed);
  const Components z = parse_components("z");
  // Fixed and prescribed (only z): refused, not silently clamped or overridden.
  expect_message(
      [&] {
        solver.solve_prescribed_dofs({{{22, fixed[1]}, {0, 0, -1e-3}, z}});
      },
      "node " + std::to_string(fixed[1]) + " is both fixed");
  // Twice with different values.
  expect_message(
      [&] {
        solver.solve_prescribed_dofs({{{22, 23}, {0, 0, -1e-3}, z}, {{23}, {0, 0, -2e-3}, z}});
      },
      "node 23 component z prescribed twice with different values");
  expect_message(
      [&] {
        solver.solve_prescribed_dofs({{{22}, {0, 0, -1e-3}, {false, false, false}}});
      },
      "no component");
  expect_message([&] { solver.solve_prescribed_dofs({{{}, {0, 0, -1e-3}, z}}); }, "no node");
  expect_message(
      [&] {
        solver.solve_prescribed_dofs({{{99}, {0, 0, -1e-3}, z}});
      },
      "node 99 out of range");
  // Twice with the same value is one constraint.
  const auto once = solver.solve_prescribed_dofs({{{22}, {0, 0, -1e-3}, z}});
  const auto twice =
      solver.solve_prescribed_dofs({{{22}, {0, 0, -1e-3}, z}, {{22}, {0, 0, -1e-3}, z}});
  EXPECT_EQ((once.displacement_m - twice.displacement_m).cwiseAbs().maxCoeff(), 0.0);
  // Per-dof form: a dof given twice, out of range, non-finite.
  expect_message(
      [&] {
        solver.solve_prescribed_per_dof({3 * 22 + 2, 3 * 22 + 2}, Eigen::VectorXd::Zero(2));
      },
      "node 22 axis 2 given twice");
  expect_message([&] { solver.solve_prescribed_per_dof({3 * 27}, Eigen::VectorXd::Zero(1)); },
                 "dof 81 (node 27) out of range");
  expect_message(
      [&] {
        solver.solve_prescribed_per_dof({3 * 22}, Eigen::VectorXd::Constant(1, std::nan("")));
      },
      "non-finite displacement at node 22 axis 0");
  expect_message([&] { solver.solve_prescribed_per_dof({3 * 22}, Eigen::VectorXd::Zero(2)); },
                 "2 displacement values for 1 dofs");
}

// Two disconnected boxes in one TetMesh (two meshes' materials, stiffness ratio 1e4).
TEST(FemStaticSolver, TwoPartsEachNeedSupportAndSolveIndependently) {
  const auto a = box_mesh(BoxSpec{3, 3, 3, {0, 0, 0}, {0.03, 0.03, 0.03}});
  const auto b = box_mesh(BoxSpec{3, 3, 3, {0.05, 0, 0}, {0.08, 0.03, 0.03}});
  std::vector<mesh::Vec3> x = a.vertices();
  x.insert(x.end(), b.vertices().begin(), b.vertices().end());
  std::vector<mesh::Tet> tets = a.tets();
  const int offset = static_cast<int>(a.num_vertices());
  for (auto t : b.tets()) {
    for (int& v : t) {
      v += offset;
    }
    tets.push_back(t);
  }
  const auto both = mesh::TetMesh::build(x, tets);
  std::vector<int> ids(both.num_tets(), 0);
  std::fill(ids.begin() + static_cast<long>(a.num_tets()), ids.end(), 1);
  const MaterialMap mats = MaterialMap::per_tet({{1e6, 0.4, "brain"}, {1e10, 0.3, "bone"}}, ids);
  const auto fixed_a = nodes_where(a, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; });
  expect_message([&] { StaticSolver(both, mats, fixed_a); }, "connected part 1");
  std::vector<int> fixed = fixed_a;
  for (int v : nodes_where(b, [](const Eigen::Vector3d& p) { return p.z() < 1e-9; })) {
    fixed.push_back(v + offset);
  }
  const StaticSolver solver(both, mats, fixed);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
  const auto top_a = nodes_where(a, [](const Eigen::Vector3d& p) { return p.z() > 0.03 - 1e-9; });
  for (int v : top_a) {
    f[3 * v] = 0.1;
    f[3 * (v + offset)] = 0.1;  // same load on the stiff part
  }
  const Eigen::VectorXd u = solver.solve(f);
  ASSERT_TRUE(u.allFinite());
  // Each part alone gives the same answer (no coupling through the factor).
  const StaticSolver soft(a, MaterialMap::uniform({1e6, 0.4, "brain"}), fixed_a);
  const Eigen::VectorXd ua = soft.solve(f.head(3 * a.num_vertices()));
  EXPECT_LE(testing::rel_max_diff(u.head(3 * a.num_vertices()), ua), 1e-12);
  const double soft_max = u.head(3 * a.num_vertices()).cwiseAbs().maxCoeff();
  const double stiff_max = u.tail(3 * b.num_vertices()).cwiseAbs().maxCoeff();
  std::printf("two parts: soft max |u| %.3e m, stiff max |u| %.3e m, ratio %.3e\n", soft_max,
              stiff_max, soft_max / stiff_max);
  EXPECT_GT(soft_max / stiff_max, 5e3);  // ~E ratio (Poisson ratios differ)
}

// Solves on workspaces of their own, from two threads at once, lock nothing and give the same
// displacements as the solver's shared workspace (checked by count and by value, not by time).
TEST(FemStaticSolver, OwnWorkspacesSolveConcurrentlyWithoutTheSharedLock) {
  const ClampedCube cube(5);
  const StaticSolver& solver = cube.solver;
  const Eigen::VectorXd f = cube.top_load(Eigen::Vector3d(0.1, 0.2, -0.5));
  const Eigen::VectorXd u_shared = solver.solve(f);
  Eigen::MatrixXd b = Eigen::MatrixXd::Zero(solver.num_free_dofs(), 7), x_shared;
  for (int j = 0; j < 7; ++j) b(5 * j, j) = 1.0;
  solver.solve_reduced(b, x_shared);
  const std::uint64_t uses = solver.shared_workspace_uses();
  ASSERT_GE(uses, 2u);
  double diff[2] = {0.0, 0.0};
  auto work = [&](int t) {
    SolveWorkspace ws;
    Eigen::VectorXd u;
    Eigen::MatrixXd x;
    for (int k = 0; k < 50; ++k) {
      solver.solve(f, u, ws);
      solver.solve_reduced(b, x, ws);
      diff[t] = std::max({diff[t], (u - u_shared).cwiseAbs().maxCoeff(), (x - x_shared).cwiseAbs().maxCoeff()});
    }
  };
  std::thread a(work, 0), c(work, 1);
  a.join();
  c.join();
  EXPECT_EQ(solver.shared_workspace_uses(), uses) << "a solve with its own workspace took the shared one";
  EXPECT_EQ(diff[0], 0.0);
  EXPECT_EQ(diff[1], 0.0);
}

}  // namespace
}  // namespace neurosim::fem
