// A brain press against CalculiX C3D10 on the same mesh: the bundled patient model's brain
// (neurosim-model, Colin27, seed 1) built coarse (10 mm cells, so ccx's quadratic solve takes
// seconds; the full-size 7 mm brain is compared in accuracy_bench and bench/RESULTS.md), its base
// fixed as in the scene, a patch of surface nodes around the top (within 12 mm of the topmost
// node) held and pressed 2 mm down. The measure is the force on the patch in the LINEAR tier
// (StaticSolver), at nu = 0.45 and 0.49. Measured: smoothed-tet 0.904 / 0.920 of C3D10,
// linear-tet 1.448 / 1.853 (it locks). Other node shares of smoothed-tet's deviatoric part
// (SmoothedStrain::kNodeShare, 0.5): 0.25 gives 0.969 / 0.990, 0 (selective ES/NS-FEM-T4) 1.024 /
// 1.048, but they fail the locking test's indentation (0.928 and 0.884 of C3D10 at nu 0.499).
// The gap is C3D10's own error on this coarse mesh: on the mesh split 8-fold (same geometry,
// patch and base) C3D10 drops to 0.11407 / 0.12141 N (-7.7 / -9.6 %), smoothed-tet to 0.10711 /
// 0.11433 N, linear-tet to 0.14081 / 0.17858 N; smoothed-tet here is 0.980 / 1.018 of C3D10 there
// (bench/RESULTS.md, "The brain press against C3D10: the candidates"). C3D10 is conforming, so
// its force is above the continuum's (linear-tet's above C3D10's). smoothed-tet is held within
// 10 % of C3D10 on the same mesh and at most a quarter of linear-tet's error; the 5 %
// against C3D10 on this mesh is not met (it would take a stiffer element than the refined
// answer supports).
#include "c3d10_reference.hpp"
#include "server/fem/static_solver.hpp"
#include "server/scene/compile.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

namespace neurosim::fem {
namespace {

TEST(FemBrainPress, SmoothedTetWithinTenPercentOfC3d10) {
  const auto dir = neurosim::testing::temp_dir("brain_press_model");
  const std::string cmd = (neurosim::testing::bin_dir() / "neurosim-model").string() +
                          " --cell-size 10 --name brain_press --out-dir " + dir.string() + " > " +
                          (dir / "model.log").string() + " 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << neurosim::testing::slurp(dir / "model.log");
  const scene::Model model = scene::load_model(dir / "brain_press.scene");
  const scene::LoadedMesh& brain = model.meshes.front();
  const mesh::TetMesh& m = brain.mesh;
  // The bundled brain's E (3 kPa); nu and the element set per case below.
  EXPECT_DOUBLE_EQ(brain.material.youngs_modulus_pa, 3000.0);

  int top = m.surface_vertices().front();
  for (int v : m.surface_vertices())
    if (m.vertices()[v].z() > m.vertices()[top].z()) top = v;
  std::vector<int> patch;
  for (int v : m.surface_vertices())
    if ((m.vertices()[v] - m.vertices()[top]).norm() < 0.012) patch.push_back(v);
  ASSERT_GE(patch.size(), 3u);
  const Eigen::Vector3d press(0.0, 0.0, -0.002);
  Eigen::VectorXd values(3 * static_cast<Eigen::Index>(patch.size()));
  for (std::size_t i = 0; i < patch.size(); ++i) values.segment<3>(3 * static_cast<Eigen::Index>(i)) = press;

  const testing::QuadraticMesh q = testing::quadratic(m);
  const std::vector<int> fixed_q = q.with_mid(brain.fixed_nodes);
  const std::vector<int> patch_q = q.with_mid(patch);
  std::printf("coarse brain: %zu nodes, %zu tetrahedra, %zu fixed, %zu pressed (C3D10: %zu nodes)\n",
              m.num_vertices(), m.num_tets(), brain.fixed_nodes.size(), patch.size(), q.nodes.size());

  auto patch_force = [](const Eigen::VectorXd& reaction_n, const std::vector<int>& nodes) {
    double f = 0.0;
    for (int v : nodes) f -= reaction_n[3 * v + 2];
    return f;  // the tissue pushing back up, unit N
  };
  for (double nu : {0.45, 0.49}) {
    Material mat = brain.material;
    mat.poisson_ratio = nu;
    const CalculixResult ref = testing::solve_c3d10(
        "brain_press_nu" + std::to_string(nu), q, mat, fixed_q,
        Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(q.nodes.size())),
        {patch_q, press});
    ASSERT_EQ(ref.reaction_n.size(), 3 * static_cast<Eigen::Index>(q.nodes.size()));
    const double f_ref = patch_force(ref.reaction_n, patch_q);
    ASSERT_GT(f_ref, 0.0);
    double ratio[2] = {0.0, 0.0};
    const Element elements[2] = {Element::kSmoothedTet, Element::kLinearTet};
    for (int k = 0; k < 2; ++k) {
      mat.element = elements[k];
      const PrescribedSolution s =
          StaticSolver(m, MaterialMap::uniform(mat), brain.fixed_nodes).solve_prescribed(patch, values);
      ratio[k] = patch_force(s.reaction_n, patch) / f_ref;
    }
    std::printf("brain press 2 mm, nu %.2f: C3D10 %.5f N; smoothed-tet / C3D10 = %.4f, "
                "linear-tet / C3D10 = %.4f\n",
                nu, f_ref, ratio[0], ratio[1]);
    char key[64];
    std::snprintf(key, sizeof key, "smoothed_over_c3d10_nu_%.2f", nu);
    ::testing::Test::RecordProperty(key, std::to_string(ratio[0]));
    EXPECT_NEAR(ratio[0], 1.0, 0.10) << "nu " << nu;
    EXPECT_LT(std::abs(ratio[0] - 1.0), 0.25 * std::abs(ratio[1] - 1.0)) << "nu " << nu;
    EXPECT_GT(ratio[1], 1.0) << "nu " << nu;  // linear-tet locks: stiffer than C3D10
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::fem
