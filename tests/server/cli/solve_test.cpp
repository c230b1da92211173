// neurosim-solve end to end: its CSV output agrees with CalculiX (ccx) on the same problem, and
// with the monolithic tied system for a coupled scene.
#include "server/fem/assembly.hpp"
#include "server/fem/calculix.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/SparseCholesky>

#include <sys/stat.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace neurosim {
namespace {

namespace fs = std::filesystem;

struct CsvRows {
  std::string header;
  std::vector<std::vector<double>> rows;
};

CsvRows read_csv(const fs::path& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  CsvRows out;
  std::getline(in, out.header);
  std::string line;
  while (std::getline(in, line)) {
    std::vector<double> row;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) row.push_back(std::stod(cell));
    out.rows.push_back(row);
  }
  return out;
}

int run_solve(const fs::path& scene, const fs::path& out, const std::string& extra = "") {
  const std::string cmd = (testing::bin_dir() / "neurosim-solve").string() + " --scene " +
                          scene.string() + " --out " + out.string() + " " + extra + " > " +
                          (out.string() + ".log") + " 2>&1";
  return std::system(cmd.c_str());
}

// Solves `scene` with neurosim-solve and the same problem (mesh `mesh_id`) with ccx (linear, or
// with `nlgeom` the neo-Hookean NLGEOM step against `--tier nonlinear`).
void expect_agrees_with_calculix(const fs::path& scene_path, const std::string& mesh_id,
                                 double tolerance, bool nlgeom = false) {
  const auto dir = testing::temp_dir("solve_ccx");
  // CalculiX's C3D4 is the linear-tet element (the scene's default anp-tet is checked in
  // tests/server/fem against C3D10).
  ASSERT_EQ(run_solve(scene_path, dir / "out",
                      "--uncoupled --element linear-tet --mesh " + mesh_id +
                          (nlgeom ? " --tier nonlinear" : "")),
            0)
      << "see " << (dir / "out").string() << ".log";
  const CsvRows csv = read_csv(dir / "out" / "displacement.csv");
  EXPECT_EQ(csv.header, "node,x,y,z,ux,uy,uz");

  // The same mesh (the generator is seeded), loads and constraints, from the compiled scene.
  const scene::Model model = scene::load_model(scene_path);
  const int mi = model.find_mesh(mesh_id);
  ASSERT_GE(mi, 0);
  const auto& lm = model.meshes[static_cast<std::size_t>(mi)];
  const int n = static_cast<int>(lm.mesh.num_vertices());
  ASSERT_EQ(csv.rows.size(), static_cast<std::size_t>(n));

  fem::Material linear = lm.material;  // as --element linear-tet (run_calculix refuses others)
  linear.element = fem::Element::kLinearTet;
  fem::CalculixLoads loads;
  loads.fixed_nodes = lm.fixed_nodes;
  loads.forces_n = Eigen::VectorXd::Zero(3 * n);
  for (const auto& l : model.loads) {
    if (l.mesh != mi) continue;
    for (int node : l.nodes) loads.forces_n.segment<3>(3 * node) += l.force_per_node_n;
  }
  for (const auto& p : model.prescribed) {
    if (p.mesh != mi) continue;
    loads.prescribed_sets.push_back(fem::PrescribedDofs{p.nodes, p.displacement_m, p.components});
  }
  loads.step.neo_hookean_nlgeom = nlgeom;
  const auto ccx =
      fem::run_calculix(dir / "ccx", "job", lm.mesh, fem::MaterialMap::uniform(linear), loads);
  double max_u = 0.0, max_diff = 0.0;
  for (int i = 0; i < n; ++i) {
    // Same node numbering and coordinates.
    ASSERT_NEAR(csv.rows[i][1], lm.mesh.vertices()[i].x(), 1e-15);
    for (int a = 0; a < 3; ++a) {
      const double ours = csv.rows[i][4 + a];
      ASSERT_TRUE(std::isfinite(ours));
      max_u = std::max(max_u, std::abs(ccx.displacement_m[3 * i + a]));
      max_diff = std::max(max_diff, std::abs(ours - ccx.displacement_m[3 * i + a]));
    }
  }
  ASSERT_GT(max_u, 0.0);
  // Reactions of every constrained node (fixed and prescribed): ccx's RF is K u at the node, so
  // a load applied there is added back to ours (K u - f).
  const CsvRows rf = read_csv(dir / "out" / "reactions.csv");
  EXPECT_EQ(rf.header, "node,x,y,z,rx,ry,rz");
  double max_rf = 0.0, max_rf_diff = 0.0;
  std::size_t compared = 0;
  for (const auto& row : rf.rows) {
    const int node = static_cast<int>(row[0]);
    ASSERT_TRUE(node >= 0 && node < n);
    if (!ccx.has_reaction[static_cast<std::size_t>(node)]) continue;
    ++compared;
    for (int a = 0; a < 3; ++a) {
      const double ours = row[4 + a] + loads.forces_n[3 * node + a];
      max_rf = std::max(max_rf, std::abs(ccx.reaction_n[3 * node + a]));
      max_rf_diff = std::max(max_rf_diff, std::abs(ours - ccx.reaction_n[3 * node + a]));
    }
  }
  EXPECT_GT(compared, 0u);
  std::cout << scene_path.filename().string() << " / " << mesh_id << ": " << n
            << " nodes, max |u| = " << max_u
            << " m, max |u - u_ccx| / max |u| = " << max_diff / max_u << ", " << compared
            << " reactions, max |r - r_ccx| / max |r| = "
            << (max_rf > 0 ? max_rf_diff / max_rf : 0.0) << "\n";
  EXPECT_LE(max_diff / max_u, tolerance);
  if (max_rf > 0) {
    EXPECT_LE(max_rf_diff / max_rf, 10 * tolerance);
  }
  fs::remove_all(dir);
}

// The cube/cylinder scene has a TIE coupling: the cube (carved) and the cylinder are solved as
// one body. Reference: the monolithic system of both meshes with the tie as a linear constraint,
// u_B(tied node k) = sum_a w_a u_A(a), eliminated (u = T q), K_q = T^T diag(K_A, K_B) T, the
// prescribed dofs moved to the right-hand side, solved by sparse LDL^T. Same carved host, fixed
// nodes and coupling map as the server (from Simulation::build).
TEST(SolveCli, CoupledSceneMatchesTheMonolithicTiedSystem) {
  const fs::path scene_path = testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const auto dir = testing::temp_dir("solve_tie");
  ASSERT_EQ(run_solve(scene_path, dir / "out"), 0) << "see " << (dir / "out").string() << ".log";
  const CsvRows cube_csv = read_csv(dir / "out" / "cube" / "displacement.csv");
  const CsvRows cyl_csv = read_csv(dir / "out" / "cylinder" / "displacement.csv");

  scene::Scene s = scene::read_scene(scene_path);
  ASSERT_TRUE(s.effects().coupling());
  s.mutable_effects()->set_tool_contact(false);
  s.clear_tools();
  scene::Model model = scene::compile(s, scene_path.string());
  const auto sim = interaction::Simulation::build(model);
  const int a = scene::find_mesh(s, "cube"), b = scene::find_mesh(s, "cylinder");
  const interaction::CoupledBody* body = sim->body_of(a);
  ASSERT_NE(body, nullptr);
  ASSERT_EQ(body->ties().size(), 1u);
  const auto& tie = body->ties()[0];
  ASSERT_EQ(tie.mesh(), b);
  const auto& mesh_a = sim->mesh(a);
  const auto& mesh_b = sim->mesh(b);
  const int na = static_cast<int>(mesh_a.num_vertices()),
            nb = static_cast<int>(mesh_b.num_vertices());
  ASSERT_EQ(cube_csv.rows.size(), static_cast<std::size_t>(na));
  ASSERT_EQ(cyl_csv.rows.size(), static_cast<std::size_t>(nb));

  // Dof kinds: A fixed -> 0, A prescribed -> value, tied B node -> combination of A dofs,
  // B fixed -> 0, else unknown.
  std::vector<int> index(3 * (na + nb), -1);  // full dof -> unknown, or -1
  std::vector<double> value(3 * (na + nb), 0.0);
  std::vector<char> known(3 * (na + nb), 0);
  for (int v : sim->fixed_nodes(a))
    for (int c = 0; c < 3; ++c) known[3 * v + c] = 1;
  for (int v : sim->fixed_nodes(b))
    for (int c = 0; c < 3; ++c) known[3 * (na + v) + c] = 1;
  int num_prescribed = 0;
  for (const auto& p : s.prescribed()) {
    ASSERT_EQ(p.mesh(), "cube");
    for (int v : scene::select_nodes(mesh_a, p.region(), "prescribed")) {
      ++num_prescribed;
      for (int c = 0; c < 3; ++c) {
        known[3 * v + c] = 1;
        value[3 * v + c] = scene::to_vec3(p.displacement_m())[c];
      }
    }
  }
  ASSERT_GT(num_prescribed, 0);
  std::vector<int> tied_row(nb, -1);
  for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k)
    tied_row[tie.tied_nodes()[k]] = static_cast<int>(k);
  int nq = 0;
  for (int d = 0; d < 3 * na; ++d)
    if (!known[d]) index[d] = nq++;
  for (int v = 0; v < nb; ++v)
    for (int c = 0; c < 3; ++c)
      if (!known[3 * (na + v) + c] && tied_row[v] < 0) index[3 * (na + v) + c] = nq++;
  // u = T q + u_known: T maps unknowns to all dofs; u_known holds the prescribed values.
  std::vector<Eigen::Triplet<double>> t;
  Eigen::VectorXd u_known = Eigen::VectorXd::Zero(3 * (na + nb));
  for (int d = 0; d < 3 * na; ++d) {
    if (index[d] >= 0)
      t.emplace_back(d, index[d], 1.0);
    else
      u_known[d] = value[d];
  }
  for (int v = 0; v < nb; ++v) {
    for (int c = 0; c < 3; ++c) {
      const int d = 3 * (na + v) + c;
      if (tied_row[v] < 0) {
        if (index[d] >= 0) t.emplace_back(d, index[d], 1.0);
        continue;
      }
      for (int j = 0; j < 3; ++j) {
        const int host_dof = 3 * tie.host_nodes()[tied_row[v]][j] + c;
        const double w = tie.weights()[tied_row[v]][j];
        if (index[host_dof] >= 0)
          t.emplace_back(d, index[host_dof], w);
        else
          u_known[d] += w * value[host_dof];
      }
    }
  }
  Eigen::SparseMatrix<double> tm(3 * (na + nb), nq);
  tm.setFromTriplets(t.begin(), t.end());
  const auto& cube_entry = s.meshes(a);
  const auto k_a = fem::assemble_stiffness(
      mesh_a, fem::MaterialMap::uniform(scene::to_material(cube_entry.material(), "cube")));
  const auto k_b = fem::assemble_stiffness(mesh_b, fem::MaterialMap::uniform(tie.material()));
  std::vector<Eigen::Triplet<double>> kt;
  for (int k = 0; k < k_a.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(k_a, k); it; ++it)
      kt.emplace_back(static_cast<int>(it.row()), static_cast<int>(it.col()), it.value());
  for (int k = 0; k < k_b.outerSize(); ++k)
    for (Eigen::SparseMatrix<double>::InnerIterator it(k_b, k); it; ++it)
      kt.emplace_back(3 * na + static_cast<int>(it.row()), 3 * na + static_cast<int>(it.col()),
                      it.value());
  Eigen::SparseMatrix<double> k_full(3 * (na + nb), 3 * (na + nb));
  k_full.setFromTriplets(kt.begin(), kt.end());
  const Eigen::SparseMatrix<double> k_q = tm.transpose() * k_full * tm;
  const Eigen::VectorXd rhs = -(tm.transpose() * (k_full * u_known));
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(k_q);
  ASSERT_EQ(ldlt.info(), Eigen::Success);
  const Eigen::VectorXd u_ref = tm * ldlt.solve(rhs) + u_known;

  auto compare = [&](const CsvRows& csv, int offset, int n, const char* name) {
    double max_u = 0.0, max_diff = 0.0;
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) {
        const double ref = u_ref[3 * (offset + i) + c];
        max_u = std::max(max_u, std::abs(ref));
        max_diff = std::max(max_diff, std::abs(csv.rows[i][4 + c] - ref));
      }
    std::cout << name << ": max |u| = " << max_u << " m, max |u - u_monolithic| = " << max_diff
              << " m\n";
    EXPECT_GT(max_u, 1e-4) << name << " does not move";
    EXPECT_LE(max_diff, 1e-8 * max_u) << name;
  };
  compare(cube_csv, 0, na, "cube");
  compare(cyl_csv, na, nb, "cylinder");

  // The whole cube on its own (--uncoupled) is stiffer than the carved cube holding the softer
  // cylinder (E 0.1 MPa where the cube has 1 MPa): the push forces differ.
  ASSERT_EQ(run_solve(scene_path, dir / "alone", "--uncoupled --mesh cube"), 0);
  EXPECT_FALSE(fs::exists(dir / "alone" / "cylinder" / "displacement.csv"));
  auto total_force = [&](const fs::path& reactions, const std::vector<char>& at) {
    const CsvRows r = read_csv(reactions);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    for (const auto& row : r.rows)
      if (at[static_cast<std::size_t>(row[0])]) sum += Eigen::Vector3d(row[4], row[5], row[6]);
    return sum;
  };
  std::vector<char> prescribed_node(na, 0);
  for (const auto& p : s.prescribed())
    for (int v : scene::select_nodes(mesh_a, p.region(), "prescribed")) prescribed_node[v] = 1;
  const Eigen::Vector3d f_tied =
      total_force(dir / "out" / "cube" / "reactions.csv", prescribed_node);
  const Eigen::Vector3d f_alone =
      total_force(dir / "alone" / "cube" / "reactions.csv", prescribed_node);
  std::cout << "push force tied " << f_tied.transpose() << " N, alone " << f_alone.transpose()
            << " N\n";
  EXPECT_LT(f_tied.x(), 0.0);
  EXPECT_GT(std::abs(f_tied.x() - f_alone.x()), 0.01 * std::abs(f_tied.x()));
  fs::remove_all(dir);
}

// Loads go on the host of a tied body: one on the embedded mesh is refused, naming it.
TEST(SolveCli, LoadOnATiedEmbeddedMeshIsRefused) {
  const auto dir = testing::temp_dir("solve_tie_load");
  const fs::path scene_path = testing::source_dir() / "scenes" / "cube_cylinder.scene";
  {
    std::ofstream out(dir / "pull.scene");
    out << testing::slurp(scene_path)
        << "\nloads { mesh: \"cylinder\" region { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 1 y: "
           "1 z: 1 } } } force_n { x: 1 } distribution: TOTAL_SPLIT_EQUALLY }\n";
  }
  EXPECT_NE(run_solve(dir / "pull.scene", dir / "out"), 0);
  const std::string text = testing::slurp(dir / "out.log");
  EXPECT_NE(text.find("\"cylinder\" is tied to \"cube\""), std::string::npos) << text;
  EXPECT_NE(text.find("pull.scene"), std::string::npos) << text;
  fs::remove_all(dir);
}

// Coupled solves run one material per mesh: a tissue whose own material has the mesh's E and nu
// (brain_skull's cerebellum) is solved; a different one is refused naming the tissue, and solved
// by --uncoupled (per-tetrahedron materials), never run with the mesh's values. On the tests' 7 mm
// brain_skull (test_support.hpp brain7_scene: the bundled scene's tissues, materials, skull and
// artery on a coarser brain): the material check does not depend on the cell size, the solves'
// time does.
TEST(SolveCli, CoupledSolveTakesTissuesOfTheMeshMaterialAndRefusesOthers) {
  const auto dir = testing::temp_dir("solve_tissues");
  const fs::path brain_skull = testing::brain7_scene("brain_skull");
  const fs::path scenes = brain_skull.parent_path();
  ASSERT_EQ(run_solve(brain_skull, dir / "same"), 0) << testing::slurp(dir / "same.log");
  std::string text = testing::slurp(brain_skull);
  for (std::size_t at = 0; (at = text.find("\"brain_skull/", at)) != std::string::npos;)
    text.replace(at + 1, 0, scenes.string() + "/");
  const std::string cerebellum = "name: \"cerebellum_literature\"\n      youngs_modulus_pa: 3000";
  const auto at = text.find(cerebellum);
  ASSERT_NE(at, std::string::npos);
  text.replace(at + cerebellum.size() - 4, 4, "1500");
  {
    std::ofstream out(dir / "soft_cerebellum.scene");
    out << text;
  }
  EXPECT_NE(run_solve(dir / "soft_cerebellum.scene", dir / "coupled"), 0);
  const std::string log = testing::slurp(dir / "coupled.log");
  EXPECT_NE(log.find("soft_cerebellum.scene: mesh \"brain\", tissue \"cerebellum\": its own "
                     "material differs"),
            std::string::npos)
      << log;
  EXPECT_EQ(run_solve(dir / "soft_cerebellum.scene", dir / "uncoupled", "--uncoupled --mesh brain"),
            0)
      << testing::slurp(dir / "uncoupled.log");
  fs::remove_all(dir);
}

TEST(SolveCli, BundledCubeAgreesWithCalculix) {
  expect_agrees_with_calculix(testing::source_dir() / "scenes" / "cube_cylinder.scene", "cube",
                              1e-6);
}

TEST(SolveCli, CantileverBeamUnderEndLoadAgreesWithCalculix) {
  const auto dir = testing::temp_dir("beam_scene");
  {
    std::ofstream out(dir / "beam.scene");
    out << R"(name: "beam"
meshes {
  id: "beam"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.1 y: 0.01 z: 0.01 } } cell_size_m: 0.003 seed: 2 }
  material { youngs_modulus_pa: 2e6 poisson_ratio: 0.3 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1e-9 y: 1 z: 1 } } }
}
loads { mesh: "beam" region { box { min_m { x: 0.0999999 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1 } } }
        force_n { z: -0.01 } distribution: TOTAL_SPLIT_EQUALLY }
)";
  }
  expect_agrees_with_calculix(dir / "beam.scene", "beam", 1e-6);
  fs::remove_all(dir);
}

// A validation case as CalculiX writes it: *BOUNDARY NTOP,3,3 (only uz held on the top face,
// ux and uy free), the bottom fixed. The top spreads sideways (Poisson), so the free components
// really were free.
TEST(SolveCli, BlockPressedOnUzOnlyAgreesWithCalculix) {
  const auto dir = testing::temp_dir("press_z_scene");
  {
    std::ofstream out(dir / "press_z.scene");
    out << R"(name: "press_z"
meshes {
  id: "block"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 z: 0.02 } } cell_size_m: 0.004 seed: 3 }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-9 } } }
}
prescribed { mesh: "block" region { box { min_m { x: -1 y: -1 z: 0.0199999 } max_m { x: 1 y: 1 z: 1 } } }
             displacement_m { z: -0.001 } components: "z" }
)";
  }
  expect_agrees_with_calculix(dir / "press_z.scene", "block", 1e-6);
  // The pressed nodes moved sideways: ux, uy were not held.
  ASSERT_EQ(run_solve(dir / "press_z.scene", dir / "out"), 0);
  const CsvRows csv = read_csv(dir / "out" / "displacement.csv");
  double max_lateral = 0.0;
  for (const auto& row : csv.rows)
    if (row[3] > 0.0199999) max_lateral = std::max({max_lateral, std::abs(row[4]), std::abs(row[5])});
  EXPECT_GT(max_lateral, 1e-5) << "top face did not spread: ux/uy were clamped";
  fs::remove_all(dir);
}

// The same block pressed 30 % of its height in the nonlinear tier against CalculiX's NLGEOM
// neo-Hookean solution; the log shows the Newton residual of every increment.
TEST(SolveCli, BlockPressedThirtyPercentNonlinearTierAgreesWithCalculix) {
  const auto dir = testing::temp_dir("press_nl_scene");
  {
    std::ofstream out(dir / "press_nl.scene");
    out << R"(name: "press_nl"
meshes {
  id: "block"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 z: 0.02 } } cell_size_m: 0.004 seed: 3 }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-9 } } }
}
prescribed { mesh: "block" region { box { min_m { x: -1 y: -1 z: 0.0199999 } max_m { x: 1 y: 1 z: 1 } } }
             displacement_m { z: -0.006 } components: "z" }
)";
  }
  expect_agrees_with_calculix(dir / "press_nl.scene", "block", 1e-4, /*nlgeom=*/true);
  ASSERT_EQ(run_solve(dir / "press_nl.scene", dir / "out", "--tier nonlinear --increments 3"), 0);
  const std::string text = testing::slurp(dir / "out.log");
  EXPECT_NE(text.find("tier NONLINEAR (--tier)"), std::string::npos) << text;
  EXPECT_NE(text.find("increment 3 load factor 1: Newton residual"), std::string::npos)
      << text;
  // A tier name the build does not know is refused.
  EXPECT_NE(run_solve(dir / "press_nl.scene", dir / "bad", "--tier hyperelastic"), 0);
  fs::remove_all(dir);
}

// The bundled coupled scene (cube with the tied cylinder) in every tier: with the press scaled
// down to 5 nm the corotational and nonlinear solves (all meshes in one Newton system, the tie
// eliminated exactly) agree with the linear coupled solve (Woodbury operator) to 1e-6 in both
// meshes' displacements; at the scene's 5 mm they differ visibly and keep the tie to round-off.
TEST(SolveCli, CoupledSceneSolvesInEveryTier) {
  const auto dir = testing::temp_dir("solve_tie_tiers");
  std::string text = testing::slurp(testing::source_dir() / "scenes" / "cube_cylinder.scene");
  const std::string press = "displacement_m { x: -0.005 y: 0 z: 0 }";
  const auto at = text.find(press);
  ASSERT_NE(at, std::string::npos);
  std::string tiny = text;
  tiny.replace(at, press.size(), "displacement_m { x: -5e-9 y: 0 z: 0 }");
  // Mesh files are generated (no relative paths), so the copies can live in the temp folder.
  std::ofstream(dir / "tiny.scene") << tiny;
  auto max_rel = [&](const fs::path& a, const fs::path& b) {
    const CsvRows ra = read_csv(a), rb = read_csv(b);
    double mx = 0.0, d = 0.0;
    for (std::size_t i = 0; i < ra.rows.size(); ++i) {
      for (int k = 4; k < 7; ++k) {
        mx = std::max(mx, std::abs(ra.rows[i][k]));
        d = std::max(d, std::abs(ra.rows[i][k] - rb.rows[i][k]));
      }
    }
    return d / mx;
  };
  ASSERT_EQ(run_solve(dir / "tiny.scene", dir / "linear"), 0);
  EXPECT_NE(run_solve(dir / "tiny.scene", dir / "corotational", "--tier corotational"), 0);
  EXPECT_NE(testing::slurp(dir / "corotational.log").find("withdrawn"), std::string::npos);
  for (const std::string tier : {"nonlinear"}) {
    ASSERT_EQ(run_solve(dir / "tiny.scene", dir / tier, "--tier " + tier), 0)
        << "see " << (dir / tier).string() << ".log";
    for (const std::string mesh : {"cube", "cylinder"}) {
      const double rel = max_rel(dir / "linear" / mesh / "displacement.csv",
                                 dir / tier / mesh / "displacement.csv");
      std::cout << tier << " / " << mesh << " at 5 nm: max |u - u_linear| / max |u_linear| = "
                << rel << "\n";
      EXPECT_LT(rel, 1e-6) << tier << " " << mesh;
    }
  }
  ASSERT_EQ(run_solve(testing::source_dir() / "scenes" / "cube_cylinder.scene", dir / "nl5mm",
                      "--tier nonlinear"),
            0);
  const std::string out = testing::slurp(dir / "nl5mm.log");
  EXPECT_NE(out.find("tier NONLINEAR (--tier)"), std::string::npos) << out;
  EXPECT_NE(out.find("tied: cylinder"), std::string::npos) << out;
  fs::remove_all(dir);
}

// A components string that is not a subset of "xyz" is refused naming the field.
TEST(SolveCli, BadComponentsAreRefused) {
  const auto dir = testing::temp_dir("bad_components");
  {
    std::ofstream out(dir / "bad_components.scene");
    out << R"(name: "bad"
meshes {
  id: "block"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 z: 0.02 } } cell_size_m: 0.01 }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-9 } } }
}
prescribed { mesh: "block" region { box { min_m { x: -1 y: -1 z: 0.0199999 } max_m { x: 1 y: 1 z: 1 } } }
             displacement_m { z: -0.001 } components: "zw" }
)";
  }
  EXPECT_NE(run_solve(dir / "bad_components.scene", dir / "out"), 0);
  const std::string text = testing::slurp(dir / "out.log");
  EXPECT_NE(text.find("bad_components.scene"), std::string::npos) << text;
  EXPECT_NE(text.find("prescribed[0].components"), std::string::npos) << text;
  fs::remove_all(dir);
}

// Values each within the scene validator's ranges (E = 1 Pa, 1e6 N) that together move the
// block by ~1e10 m: not a solution of this scene. An error naming the mesh, exit non-zero, no
// results written.
TEST(SolveCli, ImplausibleResultIsAnErrorNotASolution) {
  const auto dir = testing::temp_dir("implausible");
  {
    std::ofstream out(dir / "soft.scene");
    out << R"(name: "soft"
meshes {
  id: "block"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 z: 0.02 } } cell_size_m: 0.01 }
  material { youngs_modulus_pa: 1 poisson_ratio: 0.3 }
  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-9 } } }
}
loads { mesh: "block" region { box { min_m { x: -1 y: -1 z: 0.0199999 } max_m { x: 1 y: 1 z: 1 } } }
        force_n { x: 1e6 } }
)";
  }
  EXPECT_NE(run_solve(dir / "soft.scene", dir / "out"), 0);
  const std::string text = testing::slurp(dir / "out.log");
  EXPECT_NE(text.find("soft.scene: mesh \"block\": max |u| = "), std::string::npos) << text;
  EXPECT_NE(text.find("times the scene's size"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(dir / "out" / "displacement.csv"));
  fs::remove_all(dir);
}

TEST(SolveCli, BadSceneGivesClearErrorAndNonZeroExit) {
  const auto dir = testing::temp_dir("bad_scene");
  {
    std::ofstream out(dir / "bad.scene");
    out << "meshes { id: \"a\" material { youngs_modulus_pa: -5 poisson_ratio: 0.3 }\n"
           "  generate { box { max_m { x: 1 y: 1 z: 1 } } cell_size_m: 0.5 } }\n";
  }
  EXPECT_NE(run_solve(dir / "bad.scene", dir / "out"), 0);
  const std::string text = testing::slurp(dir / "out.log");
  EXPECT_NE(text.find("bad.scene"), std::string::npos) << text;
  EXPECT_NE(text.find("meshes[0].material"), std::string::npos) << text;
  fs::remove_all(dir);
}

// neurosim-solve under `timeout 120` (a load that blocks or runs for minutes fails the test
// instead of hanging it) and `prefix` (e.g. prlimit): exit status, seconds taken, the log.
struct Bounded {
  int status{-1};
  double seconds{0};
  std::string log;
};
Bounded run_solve_bounded(const fs::path& scene, const fs::path& out, const std::string& extra,
                          const std::string& prefix = "") {
  const std::string cmd = "timeout 120 " + prefix + " " +
                          (testing::bin_dir() / "neurosim-solve").string() + " --scene " +
                          scene.string() + " --out " + out.string() + " " + extra + " > " +
                          out.string() + ".log 2>&1";
  const auto t0 = std::chrono::steady_clock::now();
  const int rc = std::system(cmd.c_str());
  Bounded b;
  b.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  b.status = WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  b.log = testing::slurp(out.string() + ".log");
  return b;
}

// cube_cylinder.scene with its cube generated at `vertices`.
fs::path cube_scene_with(int vertices, const fs::path& dir) {
  std::string text = testing::slurp(testing::source_dir() / "scenes/cube_cylinder.scene");
  const std::string small = "target_vertices: 1812";
  EXPECT_NE(text.find(small), std::string::npos) << "cube_cylinder.scene changed its cube";
  text.replace(text.find(small), small.size(), "target_vertices: " + std::to_string(vertices));
  const fs::path scene = dir / ("cube_" + std::to_string(vertices) + ".scene");
  std::ofstream(scene) << text;
  return scene;
}

// A mesh file that is a named pipe no one writes to: refused at once naming it (it blocked the
// load for ever: opening a pipe for reading waits for a writer).
TEST(SolveCli, MeshFileThatIsANamedPipeIsRefusedAtOnce) {
  const auto dir = testing::temp_dir("solve_fifo");
  ASSERT_EQ(::mkfifo((dir / "pipe.mesh").c_str(), 0600), 0);
  std::ofstream(dir / "fifo.scene")
      << "meshes { id: \"t\" file: \"pipe.mesh\"\n"
         "  material { youngs_modulus_pa: 1e6 poisson_ratio: 0.3 }\n"
         "  fixed { nodes { ids: 0 } } }\n"
         "loads { mesh: \"t\" region { nodes { ids: 1 } } force_n { z: -0.5 } }\n";
  const Bounded b = run_solve_bounded(dir / "fifo.scene", dir / "out", "");
  EXPECT_EQ(b.status, 1) << b.log;
  EXPECT_NE(b.log.find((dir / "pipe.mesh").string() + ": mesh file: is a named pipe, not a regular file"),
            std::string::npos)
      << b.log;
  fs::remove_all(dir);
}

// A generated mesh inside the scene's limits (target_vertices 140,000 <= 300,000) but far too
// large for the memory this process may use (an address-space limit of 2 GiB here; the same
// mesh grew to 5.7 GB and ended in a bare std::bad_alloc): refused before the mesher runs, with
// the estimate, the scene, the mesh and the field.
TEST(SolveCli, GeneratedMeshTooLargeForTheMemoryIsRefusedBeforeMeshing) {
  const auto dir = testing::temp_dir("solve_memory");
  const fs::path scene = cube_scene_with(140000, dir);
  const Bounded b = run_solve_bounded(scene, dir / "out", "", "prlimit --as=2147483648 --");
  EXPECT_EQ(b.status, 1) << b.log;
  EXPECT_LT(b.seconds, 60.0) << "refused before meshing, not after: " << b.log;
  EXPECT_NE(b.log.find(scene.string() + ": mesh \"cube\": generate.target_vertices: 140000: "
                       "loading a mesh of about 1.4e+05 vertices and building its simulation "
                       "needs about 6.59 GB"),
            std::string::npos)
      << b.log;
  EXPECT_NE(b.log.find("(RLIMIT_AS): give fewer target_vertices"), std::string::npos) << b.log;
  EXPECT_EQ(b.log.find("bad_alloc"), std::string::npos) << b.log;
  fs::remove_all(dir);
}

// A load that takes longer than --load-timeout (a 30,000-vertex cube: tens of seconds of
// meshing) ends after the limit with status 1, naming the limit and the scene.
TEST(SolveCli, LoadLongerThanTheLoadTimeoutEndsNamingIt) {
  const auto dir = testing::temp_dir("solve_load_timeout");
  const fs::path scene = cube_scene_with(30000, dir);
  const Bounded b = run_solve_bounded(scene, dir / "out", "--load-timeout 1");
  EXPECT_EQ(b.status, 1) << b.log;
  EXPECT_NE(b.log.find("neurosim-solve: error: the load took longer than 1 s (--load-timeout) "
                       "while loading the scene " + scene.string() + ": exiting"),
            std::string::npos)
      << b.log;
  EXPECT_LT(b.seconds, 60.0) << b.log;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace neurosim
