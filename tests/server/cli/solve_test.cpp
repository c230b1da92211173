// neurosim-solve end to end: its CSV output agrees with CalculiX (ccx) on the same problem.
#include "server/fem/calculix.hpp"
#include "server/scene/scene.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

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

// Solves `scene` with neurosim-solve and the same problem (mesh `mesh_id`) with ccx.
void expect_agrees_with_calculix(const fs::path& scene_path, const std::string& mesh_id,
                                 double tolerance) {
  const auto dir = testing::temp_dir("solve_ccx");
  ASSERT_EQ(run_solve(scene_path, dir / "out", "--mesh " + mesh_id), 0)
      << "see " << (dir / "out").string() << ".log";
  const CsvRows csv = read_csv(dir / "out" / "displacement.csv");
  EXPECT_EQ(csv.header, "node,x,y,z,ux,uy,uz");

  // The same mesh (the generator is seeded), loads and constraints, in process.
  const scene::Scene s = scene::read_scene(scene_path);
  const auto& entry = s.meshes(scene::find_mesh(s, mesh_id));
  const auto lm = scene::load_mesh(entry, scene_path.parent_path(), scene_path.string());
  const int n = static_cast<int>(lm.mesh.num_vertices());
  ASSERT_EQ(csv.rows.size(), static_cast<std::size_t>(n));

  fem::CalculixLoads loads;
  loads.fixed_nodes = lm.fixed_nodes;
  loads.forces_n = Eigen::VectorXd::Zero(3 * n);
  for (const auto& l : s.loads()) {
    if (l.mesh() != mesh_id) continue;
    const auto nodes = scene::select_nodes(lm.mesh, l.region(), "load");
    mesh::Vec3 f = scene::to_vec3(l.force_n());
    if (l.distribution() == scene::Load::TOTAL_SPLIT_EQUALLY) f /= static_cast<double>(nodes.size());
    for (int node : nodes) loads.forces_n.segment<3>(3 * node) += f;
  }
  std::vector<double> prescribed;
  for (const auto& p : s.prescribed()) {
    if (p.mesh() != mesh_id) continue;
    for (int node : scene::select_nodes(lm.mesh, p.region(), "prescribed")) {
      loads.prescribed_nodes.push_back(node);
      const mesh::Vec3 d = scene::to_vec3(p.displacement_m());
      prescribed.insert(prescribed.end(), {d.x(), d.y(), d.z()});
    }
  }
  loads.prescribed_displacements_m = Eigen::Map<Eigen::VectorXd>(prescribed.data(), prescribed.size());
  const auto ccx = fem::run_calculix(dir / "ccx", "job", lm.mesh,
                                     fem::MaterialMap::uniform(lm.material), loads);

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
  std::cout << scene_path.filename().string() << " / " << mesh_id << ": " << n
            << " nodes, max |u| = " << max_u << " m, max |u - u_ccx| / max |u| = "
            << max_diff / max_u << "\n";
  EXPECT_LE(max_diff / max_u, tolerance);
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

TEST(SolveCli, BadSceneGivesClearErrorAndNonZeroExit) {
  const auto dir = testing::temp_dir("bad_scene");
  {
    std::ofstream out(dir / "bad.scene");
    out << "meshes { id: \"a\" material { youngs_modulus_pa: -5 poisson_ratio: 0.3 }\n"
           "  generate { box { max_m { x: 1 y: 1 z: 1 } } cell_size_m: 0.5 } }\n";
  }
  EXPECT_NE(run_solve(dir / "bad.scene", dir / "out"), 0);
  std::ifstream log(dir.string() + "/out.log");
  std::stringstream text;
  text << log.rdbuf();
  EXPECT_NE(text.str().find("bad.scene"), std::string::npos) << text.str();
  EXPECT_NE(text.str().find("meshes[0].material"), std::string::npos) << text.str();
  fs::remove_all(dir);
}

}  // namespace
}  // namespace neurosim
