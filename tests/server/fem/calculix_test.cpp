// Against CalculiX: the same mesh, material(s), fixed nodes and loads written as a C3D4 deck,
// solved by `ccx` in a temporary directory; nodal displacements agree to 1e-6 relative.
// Hard cases: nu = 0.49 / 0.499, stiffness ratio 1e4, a sliver element.
#include "server/fem/calculix.hpp"
#include "fem_test_meshes.hpp"
#include "server/fem/static_solver.hpp"
#include "server/fem/tet_element.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <fstream>

namespace neurosim::fem {
namespace {

using testing::box_mesh;
using testing::BoxSpec;
using testing::nodes_where;

struct Comparison {
  double u_rel{0.0};   // max |u - u_ccx| / max |u_ccx|
  double rf_rel{0.0};  // same for reactions at fixed / prescribed nodes
  double max_u_m{0.0};
};

// Solves with neurosim and with ccx, compares. Prescribed by component (prescribed_sets) goes
// through StaticSolver::solve_prescribed_dofs, with prescribed_nodes as all-component sets.
Comparison compare_with_ccx(const std::string& tag, const mesh::TetMesh& m, const MaterialMap& mats,
                            const CalculixLoads& loads, ConditionEstimate* cond = nullptr,
                            PrescribedSolution* ours_out = nullptr,
                            CalculixResult* ccx_out = nullptr) {
  const StaticSolver solver(m, mats, loads.fixed_nodes);
  const Eigen::VectorXd forces = loads.forces_n.size() ? loads.forces_n : Eigen::VectorXd();
  PrescribedSolution ours;
  if (loads.prescribed_sets.empty()) {
    ours =
        solver.solve_prescribed(loads.prescribed_nodes, loads.prescribed_displacements_m, forces);
  } else {
    std::vector<PrescribedDofs> sets = loads.prescribed_sets;
    for (std::size_t k = 0; k < loads.prescribed_nodes.size(); ++k) {
      sets.push_back({{loads.prescribed_nodes[k]},
                      loads.prescribed_displacements_m.segment<3>(3 * k),
                      kAllComponents});
    }
    ours = solver.solve_prescribed_dofs(sets, forces);
  }
  if (cond) {
    *cond = solver.estimate_condition(500, 1e-6);
  }
  const auto dir = neurosim::testing::temp_dir("ccx_" + tag);
  const CalculixResult ccx = run_calculix(dir, tag, m, mats, loads, {"ccx", 240.0});
  Comparison c;
  c.max_u_m = ccx.displacement_m.cwiseAbs().maxCoeff();
  c.u_rel = testing::rel_max_diff(ours.displacement_m, ccx.displacement_m);
  Eigen::VectorXd rf_ours = Eigen::VectorXd::Zero(ours.reaction_n.size());
  for (std::size_t v = 0; v < m.num_vertices(); ++v) {
    if (ccx.has_reaction[v]) {
      // ccx's RF is K u at the node: loads applied on constrained dofs are not subtracted.
      rf_ours.segment<3>(3 * v) = ours.reaction_n.segment<3>(3 * v);
      if (loads.forces_n.size()) {
        rf_ours.segment<3>(3 * v) += loads.forces_n.segment<3>(3 * v);
      }
    }
  }
  c.rf_rel = testing::rel_max_diff(rf_ours, ccx.reaction_n);
  std::printf("%-28s nodes %6zu tets %7zu  max|u| %.4e m  u rel diff %.3e  RF rel diff %.3e\n",
              tag.c_str(), m.num_vertices(), m.num_tets(), c.max_u_m, c.u_rel, c.rf_rel);
  std::filesystem::remove_all(dir);
  if (ours_out) {
    *ours_out = ours;
  }
  if (ccx_out) {
    *ccx_out = ccx;
  }
  return c;
}

TEST(FemCalculix, DeckWriterAndDatReader) {
  const auto m = box_mesh(BoxSpec{1, 1, 1});
  const auto dir = neurosim::testing::temp_dir("ccx_io");
  CalculixLoads loads;
  loads.fixed_nodes = {0, 1, 2};
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  loads.forces_n[3 * 7 + 2] = -1.5;
  write_calculix_input(dir / "a.inp", m, MaterialMap::uniform({1e6, 0.3, "x"}), loads);
  std::ifstream in(dir / "a.inp");
  const std::string deck((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(deck.find("*ELEMENT, TYPE=C3D4, ELSET=E0"), std::string::npos);
  EXPECT_NE(deck.find("8, 3, -1.5"), std::string::npos) << deck;
  loads.forces_n[0] = std::nan("");
  EXPECT_THROW(write_calculix_input(dir / "b.inp", m, MaterialMap::uniform({1e6, 0.3, "x"}), loads),
               std::invalid_argument);
  // Prescribed by component: one node set per definition, *BOUNDARY lines for the prescribed
  // components only.
  loads.forces_n[0] = 0.0;
  loads.prescribed_sets = {{{6, 7}, {9.0, 0.0, -1e-3}, parse_components("z")},
                           {{4}, {0.000244140625, 0.0, 0.0}, parse_components("xy")}};
  write_calculix_input(dir / "c.inp", m, MaterialMap::uniform({1e6, 0.3, "x"}), loads);
  {
    std::ifstream in_c(dir / "c.inp");
    const std::string deck_c((std::istreambuf_iterator<char>(in_c)),
                             std::istreambuf_iterator<char>());
    EXPECT_NE(deck_c.find("*NSET, NSET=NP0\n7, 8\n"), std::string::npos) << deck_c;
    EXPECT_NE(deck_c.find("*NSET, NSET=NP1\n5\n"), std::string::npos) << deck_c;
    EXPECT_NE(
        deck_c.find("*BOUNDARY\nNP0, 3, 3, -0.001\nNP1, 1, 1, 0.000244140625\nNP1, 2, 2, 0\n"),
        std::string::npos)
        << deck_c;
    EXPECT_EQ(deck_c.find("NP0, 1, 1"), std::string::npos) << deck_c;
    EXPECT_NE(deck_c.find("*NSET, NSET=NRF\n1, 2, 3, 5, 7, 8\n"), std::string::npos) << deck_c;
  }
  // A node both fixed and prescribed, or one component given two values, is refused by name.
  loads.prescribed_sets.push_back({{2}, {0.0, 0.0, -1e-3}, parse_components("z")});
  try {
    write_calculix_input(dir / "d.inp", m, MaterialMap::uniform({1e6, 0.3, "x"}), loads);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("prescribed[2]: node 2 is both fixed"), std::string::npos)
        << e.what();
  }
  loads.prescribed_sets.back() = {{7}, {0.0, 0.0, -2e-3}, parse_components("z")};
  try {
    write_calculix_input(dir / "d.inp", m, MaterialMap::uniform({1e6, 0.3, "x"}), loads);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("node 7 component z prescribed twice"), std::string::npos)
        << e.what();
  }
  loads.prescribed_sets.clear();
  // A malformed .dat names file and line.
  {
    std::ofstream bad(dir / "bad.dat");
    bad << "\n displacements (vx,vy,vz) for set NALL and time  0.1000000E+01\n\n         1  0.0 "
           "0.0\n";
  }
  try {
    read_calculix_dat(dir / "bad.dat", m.num_vertices());
    FAIL();
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.dat:4"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The deck is C3D4, linear-tet's element: materials asking for another element are refused by
// name (the deck, and run_calculix before ccx runs), not silently solved with C3D4.
TEST(FemCalculix, RefusesElementsOtherThanLinearTet) {
  const auto m = box_mesh(BoxSpec{1, 1, 1});
  const auto dir = neurosim::testing::temp_dir("ccx_element");
  CalculixLoads loads;
  loads.fixed_nodes = {0, 1, 2, 3};
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  loads.forces_n[3 * 7 + 2] = -1.0;
  for (Element element : {Element::kAnpTet, Element::kSmoothedTet}) {
    Material mat{1e6, 0.3, "tissue"};
    mat.element = element;
    const std::string name = element_name(element);
    for (int run = 0; run < 2; ++run) {
      try {
        if (run == 0) {
          write_calculix_input(dir / "e.inp", m, MaterialMap::uniform(mat), loads);
        } else {
          CalculixRunOptions o;
          o.executable = "/nonexistent/ccx";  // refused before ccx would run
          run_calculix(dir, "e", m, MaterialMap::uniform(mat), loads, o);
        }
        ADD_FAILURE() << name << " accepted (run " << run << ")";
      } catch (const std::invalid_argument& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("material 'tissue' asks for element '" + name + "'"), std::string::npos)
            << what;
        EXPECT_NE(what.find("C3D4, which is 'linear-tet'"), std::string::npos) << what;
      }
    }
    EXPECT_FALSE(std::filesystem::exists(dir / "e.inp")) << name;
  }
  // linear-tet is written as C3D4.
  write_calculix_input(dir / "e.inp", m, MaterialMap::uniform({1e6, 0.3, "tissue"}), loads);
  std::ifstream in(dir / "e.inp");
  const std::string deck((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_NE(deck.find("*ELEMENT, TYPE=C3D4"), std::string::npos);
  std::filesystem::remove_all(dir);
}

TEST(FemCalculix, BeamMatches) {
  const auto m = box_mesh(BoxSpec{20, 2, 2, {0, 0, 0}, {1.0, 0.1, 0.1}, 0.15, 5});
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-12; });
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v : nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() > 1.0 - 1e-12; })) {
    loads.forces_n.segment<3>(3 * v) = Eigen::Vector3d(0.1, 0.05, -0.2);
  }
  const Comparison c = compare_with_ccx("beam", m, MaterialMap::uniform({1e6, 0.3, "beam"}), loads);
  EXPECT_LE(c.u_rel, 1e-6);
  EXPECT_LE(c.rf_rel, 1e-6);
}

TEST(FemCalculix, CubeWithForcesAndPrescribedDisplacementsMatches) {
  // The paper's cube material (brain, 1 MPa, nu 0.4), irregular interior, bottom fixed,
  // part of the top pushed down (prescribed) and a lateral force on one side.
  const auto m = box_mesh(BoxSpec{8, 8, 8, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 8});
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  loads.prescribed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) {
    return p.z() > 0.1 - 1e-12 && std::abs(p.x() - 0.05) < 0.021 && std::abs(p.y() - 0.05) < 0.021;
  });
  loads.prescribed_displacements_m = Eigen::VectorXd::Zero(3 * loads.prescribed_nodes.size());
  for (std::size_t k = 0; k < loads.prescribed_nodes.size(); ++k) {
    loads.prescribed_displacements_m[3 * k + 2] = -2e-3;
  }
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v :
       nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-12 && p.z() > 0.05; })) {
    loads.forces_n[3 * v] = 0.3;
  }
  const Comparison c =
      compare_with_ccx("cube", m, MaterialMap::uniform({1e6, 0.4, "brain"}), loads);
  EXPECT_LE(c.u_rel, 1e-6);
  EXPECT_LE(c.rf_rel, 1e-6);
}

TEST(FemCalculix, BlockPressedByUzOnlyMatches) {
  // Bottom fixed, the whole top pressed down 1 mm by prescribing only uz (CalculiX: NSET, 3, 3):
  // the top is free to spread sideways (Poisson expansion), with no lateral reaction.
  const auto m = box_mesh(BoxSpec{8, 8, 6, {0, 0, 0}, {0.1, 0.1, 0.06}, 0.2, 31});
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  const auto top = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.06 - 1e-12; });
  loads.prescribed_sets = {{top, {0.0, 0.0, -1e-3}, parse_components("z")}};
  PrescribedSolution ours;
  CalculixResult ccx;
  const Comparison c = compare_with_ccx("press_uz", m, MaterialMap::uniform({1e6, 0.4, "brain"}),
                                        loads, nullptr, &ours, &ccx);
  EXPECT_LE(c.u_rel, 1e-6);
  EXPECT_LE(c.rf_rel, 1e-6);
  double lateral = 0.0, lateral_ccx = 0.0, rz = 0.0, free_rf = 0.0, free_rf_ccx = 0.0;
  for (int v : top) {
    EXPECT_EQ(ours.displacement_m[3 * v + 2], -1e-3);
    lateral = std::max(lateral, ours.displacement_m.segment<2>(3 * v).cwiseAbs().maxCoeff());
    lateral_ccx = std::max(lateral_ccx, ccx.displacement_m.segment<2>(3 * v).cwiseAbs().maxCoeff());
    rz = std::max(rz, std::abs(ours.reaction_n[3 * v + 2]));
    free_rf = std::max(free_rf, ours.reaction_n.segment<2>(3 * v).cwiseAbs().maxCoeff());
    EXPECT_TRUE(ccx.has_reaction[v]);
    free_rf_ccx = std::max(free_rf_ccx, ccx.reaction_n.segment<2>(3 * v).cwiseAbs().maxCoeff());
  }
  const Eigen::VectorXd ku =
      StaticSolver(m, MaterialMap::uniform({1e6, 0.4, "brain"}), loads.fixed_nodes).stiffness() *
      ours.displacement_m;
  double free_ku = 0.0;
  for (int v : top) {
    free_ku = std::max(free_ku, ku.segment<2>(3 * v).cwiseAbs().maxCoeff());
  }
  std::printf(
      "press_uz: top lateral max |u| %.4e m (ccx %.4e m), max |RF_z| %.4e N, free "
      "components: reported %.1e N, |K u| %.3e N, ccx RF %.3e N\n",
      lateral, lateral_ccx, rz, free_rf, free_ku, free_rf_ccx);
  // Not clamped: the top spreads by ~nu * strain * half-width ~ 1e-4 m at its edges.
  EXPECT_GT(lateral, 2e-5);
  EXPECT_GT(lateral_ccx, 2e-5);
  EXPECT_EQ(free_rf, 0.0);
  EXPECT_LE(free_ku, 1e-9 * rz);
  EXPECT_LE(free_rf_ccx, 1e-6 * rz);
}

TEST(FemCalculix, RollersAndPartialPressWithForcesMatch) {
  // Bottom fixed; the x = 0 face held in x only, the y = 0 face in y only (rollers, value 0);
  // a patch of the top pushed 2 mm down in z only; a lateral load on the x = max face. Nodes on
  // both a roller face and the patch (or both rollers) hold two components from two sets.
  const auto m = box_mesh(BoxSpec{8, 8, 8, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 8});
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  const auto x0 =
      nodes_where(m, [](const Eigen::Vector3d& p) { return p.x() < 1e-12 && p.z() > 1e-12; });
  const auto y0 =
      nodes_where(m, [](const Eigen::Vector3d& p) { return p.y() < 1e-12 && p.z() > 1e-12; });
  const auto patch = nodes_where(m, [](const Eigen::Vector3d& p) {
    return p.z() > 0.1 - 1e-12 && p.x() < 0.0376 && p.y() < 0.0376;
  });
  loads.prescribed_sets = {{x0, {0.0, 0.0, 0.0}, parse_components("x")},
                           {y0, {0.0, 0.0, 0.0}, parse_components("y")},
                           {patch, {0.0, 0.0, -2e-3}, parse_components("z")}};
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v : nodes_where(
           m, [](const Eigen::Vector3d& p) { return p.x() > 0.1 - 1e-12 && p.z() > 0.05; })) {
    loads.forces_n[3 * v + 1] = 0.2;
  }
  PrescribedSolution ours;
  const Comparison c = compare_with_ccx(
      "rollers_press", m, MaterialMap::uniform({1e6, 0.45, "brain"}), loads, nullptr, &ours);
  EXPECT_LE(c.u_rel, 1e-6);
  EXPECT_LE(c.rf_rel, 1e-6);
  // The rollers hold only their normal component: the faces slide in their plane.
  double slide = 0.0;
  for (int v : x0) {
    EXPECT_EQ(ours.displacement_m[3 * v], 0.0);
    slide = std::max(slide, std::abs(ours.displacement_m[3 * v + 2]));
  }
  EXPECT_GT(slide, 1e-4);
}

TEST(FemCalculix, NearlyIncompressibleMatches) {
  const auto m = box_mesh(BoxSpec{6, 6, 6, {0, 0, 0}, {0.1, 0.1, 0.1}, 0.2, 12});
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v : nodes_where(
           m, [](const Eigen::Vector3d& p) { return p.z() > 0.1 - 1e-12 && p.x() < 0.05; })) {
    loads.forces_n.segment<3>(3 * v) = Eigen::Vector3d(0.05, 0.0, -0.2);
  }
  std::printf("%-8s %12s %12s %12s %12s %12s\n", "nu", "u rel diff", "lambda_min", "lambda_max",
              "cond(K_ff)", "rcond(L)");
  for (double nu : {0.3, 0.49, 0.499}) {
    ConditionEstimate cond;
    const Comparison c = compare_with_ccx("nu" + std::to_string(nu).substr(0, 5), m,
                                          MaterialMap::uniform({1e6, nu, "gel"}), loads, &cond);
    std::printf("%-8.3f %12.3e %12.4e %12.4e %12.4e %12.4e\n", nu, c.u_rel, cond.lambda_min,
                cond.lambda_max, cond.condition, cond.rcond_cholmod);
    EXPECT_LE(c.u_rel, 1e-6) << "nu = " << nu;
  }
}

TEST(FemCalculix, TwoMaterialsWithStiffnessRatio1e4Match) {
  // Lower half stiff (1e4 MPa-class ratio), upper half soft: one mesh, two solid sections.
  const auto m = box_mesh(BoxSpec{6, 6, 8, {0, 0, 0}, {0.1, 0.1, 0.12}, 0.15, 4});
  std::vector<int> ids(m.num_tets());
  for (std::size_t t = 0; t < m.num_tets(); ++t) {
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (int v : m.tets()[t]) {
      c += m.vertices()[v] / 4.0;
    }
    ids[t] = c.z() < 0.06 ? 1 : 0;
  }
  const MaterialMap mats = MaterialMap::per_tet({{1e6, 0.4, "brain"}, {1e10, 0.3, "bone"}}, ids);
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v : nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.12 - 1e-12; })) {
    loads.forces_n.segment<3>(3 * v) = Eigen::Vector3d(0.1, 0.0, -0.5);
  }
  ConditionEstimate cond;
  const Comparison c = compare_with_ccx("two_materials", m, mats, loads, &cond);
  std::printf("two materials: cond(K_ff) %.3e, rcond(L) %.3e\n", cond.condition,
              cond.rcond_cholmod);
  EXPECT_LE(c.u_rel, 1e-6);
  // The soft part deforms, the stiff part barely: a finite, non-trivial answer.
  EXPECT_GT(c.max_u_m, 0.0);
}

TEST(FemCalculix, SliverElementMatches) {
  // Move one interior node of a regular mesh almost onto a face of a neighbour: slivers.
  const auto base = box_mesh(BoxSpec{4, 4, 4, {0, 0, 0}, {0.04, 0.04, 0.04}});
  std::vector<mesh::Vec3> x = base.vertices();
  const int moved = testing::box_node(BoxSpec{4, 4, 4}, 2, 2, 2);
  // Nodes (2,2,2) and its neighbours: push towards the plane x + y + z = const of the diagonal.
  x[moved] += Eigen::Vector3d(0.0099, 0.0, 0.0);
  mesh::BuildOptions opt;
  opt.source = "sliver cube";
  const auto m = mesh::TetMesh::build(x, base.tets(), opt);
  double worst_ratio = 1.0, worst_dihedral = 180.0;
  for (const auto& t : m.tets()) {
    const TetQuality q = tet_quality(
        {m.vertices()[t[0]], m.vertices()[t[1]], m.vertices()[t[2]], m.vertices()[t[3]]});
    worst_ratio = std::min(worst_ratio, q.mean_ratio);
    worst_dihedral = std::min(worst_dihedral, q.min_dihedral_deg);
  }
  std::printf("sliver mesh: worst mean ratio %.3e, smallest dihedral %.4f deg\n", worst_ratio,
              worst_dihedral);
  EXPECT_LT(worst_ratio, 0.05);
  CalculixLoads loads;
  loads.fixed_nodes = nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() < 1e-12; });
  loads.forces_n = Eigen::VectorXd::Zero(3 * m.num_vertices());
  for (int v : nodes_where(m, [](const Eigen::Vector3d& p) { return p.z() > 0.04 - 1e-12; })) {
    loads.forces_n.segment<3>(3 * v) = Eigen::Vector3d(0.0, 0.02, -0.1);
  }
  const Comparison c =
      compare_with_ccx("sliver", m, MaterialMap::uniform({1e6, 0.4, "brain"}), loads);
  EXPECT_LE(c.u_rel, 1e-6);
}

}  // namespace
}  // namespace neurosim::fem
