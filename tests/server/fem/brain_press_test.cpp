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
// 10 % of C3D10 on the same mesh and at most a quarter of linear-tet's error; 5 %
// against C3D10 on this mesh is not met (it would take a stiffer element than the refined
// answer supports). The second test compares against C3D10 one split finer on the press's
// sub-model (the converged direction). Last, the Richardson extrapolation the benches take the
// converged answer from (bench/richardson.hpp), on known power laws.
#include "bench/richardson.hpp"
#include "bench/sub_model.hpp"
#include "bench/tet_split.hpp"
#include "c3d10_reference.hpp"
#include "server/fem/equilibrium_solver.hpp"
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

// The coarse Colin27 brain (neurosim-model --cell-size 10) written to dir/brain_press.scene, its
// log to dir/model.log; the command's status (0: built).
int build_coarse_brain(const std::filesystem::path& dir) {
  const std::string cmd = (neurosim::testing::bin_dir() / "neurosim-model").string() +
                          " --cell-size 10 --name brain_press --out-dir " + dir.string() + " > " +
                          (dir / "model.log").string() + " 2>&1";
  return std::system(cmd.c_str());
}

// The position of the mesh's topmost surface node (largest z), unit m.
Eigen::Vector3d top_of(const mesh::TetMesh& m) {
  int top = m.surface_vertices().front();
  for (int v : m.surface_vertices())
    if (m.vertices()[v].z() > m.vertices()[top].z()) top = v;
  return m.vertices()[top];
}

// The pressed patch: the surface nodes within 12 mm of top_x.
std::vector<int> patch_at(const mesh::TetMesh& m, const Eigen::Vector3d& top_x) {
  std::vector<int> patch;
  for (int v : m.surface_vertices())
    if ((m.vertices()[v] - top_x).norm() < 0.012) patch.push_back(v);
  return patch;
}

TEST(FemBrainPress, SmoothedTetWithinTenPercentOfC3d10) {
  const auto dir = neurosim::testing::temp_dir("brain_press_model");
  ASSERT_EQ(build_coarse_brain(dir), 0) << neurosim::testing::slurp(dir / "model.log");
  const scene::Model model = scene::load_model(dir / "brain_press.scene");
  const scene::LoadedMesh& brain = model.meshes.front();
  const mesh::TetMesh& m = brain.mesh;
  // The bundled brain's E (3 kPa); nu and the element set per case below.
  EXPECT_DOUBLE_EQ(brain.material.youngs_modulus_pa, 3000.0);

  const std::vector<int> patch = patch_at(m, top_of(m));
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

// The same press against a refined C3D10 (the converged direction), with CalculiX's runs kept
// to seconds: the press's neighbourhood (bench/sub_model.hpp: the coarse brain's tetrahedra with
// centroid within 60 mm of the top node, the cut faces clamped) and that sub-model split 1 -> 8
// (bench/tet_split.hpp: the same geometry, clamp and patch). C3D10 is conforming: with the patch
// held its force is above the continuum's and falls under refinement. Measured (LINEAR, 2 mm):
// C3D10 0.156669 / 0.178815 N on the sub-model and 0.141496 / 0.156082 N split (nu 0.45 / 0.49),
// smoothed-tet on the coarse sub-model 0.138486 / 0.160516 N: 0.979 / 1.028 of the split C3D10,
// where C3D10 on the coarse sub-model is 1.107 / 1.146 of it. Split twice more (C3D10 on 126381
// nodes, minutes of ccx: press_refinement_bench --region 60 --splits 2 --depth 2 --no-nonlinear)
// the three meshes extrapolate (Richardson) to 0.12825 N for C3D10 and 0.12695 N for smoothed-tet
// at nu 0.45 (bench/RESULTS.md, "The brain press's converged answer").
TEST(FemBrainPress, SmoothedTetWithinFivePercentOfTheRefinedC3d10) {
  const auto dir = neurosim::testing::temp_dir("brain_press_refined");
  ASSERT_EQ(build_coarse_brain(dir), 0) << neurosim::testing::slurp(dir / "model.log");
  const scene::Model model = scene::load_model(dir / "brain_press.scene");
  scene::LoadedMesh brain = model.meshes.front();
  const Eigen::Vector3d top_x = top_of(brain.mesh);
  std::vector<mesh::Tri> cut_faces = neurosim::bench::cut_region(brain, top_x, 0.060);
  const scene::LoadedMesh coarse = brain;
  const std::vector<mesh::Tri> cut0 = cut_faces;  // split_region replaces them by their children
  neurosim::bench::split_region(brain, cut_faces);
  const scene::LoadedMesh& fine = brain;

  // The patch: the coarse surface nodes within 12 mm of the top; on the split mesh those and the
  // midpoints of the edges between two of them (the same held surface).
  const std::vector<int> patch0 = patch_at(coarse.mesh, top_x);
  ASSERT_GE(patch0.size(), 3u);
  const neurosim::bench::SplitMesh split = neurosim::bench::split_tets(coarse.mesh);
  ASSERT_EQ(split.mesh.num_vertices(), fine.mesh.num_vertices());
  const std::vector<int> patch1 = neurosim::bench::split_node_set(split, patch0);
  const Eigen::Vector3d press(0.0, 0.0, -0.002);
  auto patch_force = [](const Eigen::VectorXd& reaction_n, const std::vector<int>& nodes) {
    double f = 0.0;
    for (int v : nodes) f -= reaction_n[3 * v + 2];
    return f;  // the tissue pushing back up, unit N
  };
  // C3D10 on a sub-model: exactly the cut faces clamped (their corners and the mid-nodes of
  // their edges, no other edge between two clamped nodes).
  auto c3d10 = [&](const scene::LoadedMesh& m, const std::vector<mesh::Tri>& cut,
                   const std::vector<int>& patch, const Material& mat, const std::string& tag) {
    const testing::QuadraticMesh q = testing::quadratic(m.mesh);
    const std::vector<int> fixed_q = neurosim::bench::clamp_of_faces(q, m.fixed_nodes, cut);
    const std::vector<int> patch_q = q.with_mid(patch);
    const CalculixResult r = testing::solve_c3d10(
        tag, q, mat, fixed_q, Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(q.nodes.size())),
        {patch_q, press});
    EXPECT_EQ(r.reaction_n.size(), 3 * static_cast<Eigen::Index>(q.nodes.size())) << tag;
    if (r.reaction_n.size() != 3 * static_cast<Eigen::Index>(q.nodes.size())) return std::nan("");
    return patch_force(r.reaction_n, patch_q);
  };
  std::printf("sub-model: %zu nodes, %zu tetrahedra, %zu clamped, %zu pressed; split: %zu nodes, "
              "%zu tetrahedra, %zu pressed\n",
              coarse.mesh.num_vertices(), coarse.mesh.num_tets(), coarse.fixed_nodes.size(),
              patch0.size(), fine.mesh.num_vertices(), fine.mesh.num_tets(), patch1.size());
  for (double nu : {0.45, 0.49}) {
    Material mat = coarse.material;
    mat.poisson_ratio = nu;
    char tag[64];
    std::snprintf(tag, sizeof tag, "brain_sub_nu%.2f", nu);
    const double c0 = c3d10(coarse, cut0, patch0, mat, std::string(tag) + "_coarse");
    const double c1 = c3d10(fine, cut_faces, patch1, mat, std::string(tag) + "_split");
    ASSERT_TRUE(std::isfinite(c0) && std::isfinite(c1)) << "ccx failed, nu " << nu;
    mat.element = Element::kSmoothedTet;
    Eigen::VectorXd values(3 * static_cast<Eigen::Index>(patch0.size()));
    for (std::size_t i = 0; i < patch0.size(); ++i)
      values.segment<3>(3 * static_cast<Eigen::Index>(i)) = press;
    const PrescribedSolution s = StaticSolver(coarse.mesh, MaterialMap::uniform(mat), coarse.fixed_nodes)
                                     .solve_prescribed(patch0, values);
    const double s0 = patch_force(s.reaction_n, patch0);
    std::printf("nu %.2f: C3D10 %.6f N (sub-model), %.6f N (split); smoothed-tet %.6f N on the "
                "sub-model = %.4f of the split C3D10 (C3D10 on the sub-model: %.4f of it)\n",
                nu, c0, c1, s0, s0 / c1, c0 / c1);
    EXPECT_LT(c1, c0) << "C3D10 (conforming) must fall under refinement, nu " << nu;
    EXPECT_NEAR(s0 / c1, 1.0, 0.05) << "nu " << nu;
    EXPECT_LT(std::abs(s0 / c1 - 1.0), std::abs(c0 / c1 - 1.0))
        << "smoothed-tet on the coarse mesh must be nearer the refined C3D10 than C3D10 on it, nu "
        << nu;
  }
  std::filesystem::remove_all(dir);
}

// A crushed cell does not slow Newton down: the press's 40 mm sub-model split once (961 nodes,
// 3808 tetrahedra, 15 pressed nodes), pressed 10 mm in NONLINEAR at nu 0.49 in smoothed-tet. The
// patch's edge crushes the tetrahedra beside it: without the element barrier
// (element_barrier.hpp) some were inverted and one clamped at the answer (measured: 1 clamped,
// 7 inverted, patch force 0.9317 N); with it, the tetrahedra it holds (crushed below J = 0.25)
// carry its stiff cubic energy and none inverts (measured: 1.0126 N, 0 clamped, 0 inverted;
// linear-tet, stiffer, crushes none, 3.134 N). The barrier's tangent is exact, the clamped
// element's the central difference of its C1 stress (not projected on its own: with the
// projection this solve contracted about 0.9 per full Newton step from load factor 0.98 on
// and no increment converged in 40 iterations). At most 16 iterations per increment and 4
// cutbacks, so a failure is an exception within seconds, not a solve that creeps on in tiny
// increments. Checked: the solve converges, the barrier holds some tetrahedra and none is
// inverted, the last increment converges superlinearly.
TEST(FemBrainPress, NonlinearCrushedCellsKeepNewtonSuperlinear) {
  const auto dir = neurosim::testing::temp_dir("brain_press_crushed");
  ASSERT_EQ(build_coarse_brain(dir), 0) << neurosim::testing::slurp(dir / "model.log");
  const scene::Model model = scene::load_model(dir / "brain_press.scene");
  scene::LoadedMesh brain = model.meshes.front();
  const Eigen::Vector3d top_x = top_of(brain.mesh);
  std::vector<mesh::Tri> cut_faces = neurosim::bench::cut_region(brain, top_x, 0.040);
  const std::vector<int> patch = neurosim::bench::split_node_set(
      neurosim::bench::split_tets(brain.mesh), patch_at(brain.mesh, top_x));
  neurosim::bench::split_region(brain, cut_faces);  // exactly the cut faces stay clamped
  const mesh::TetMesh& m = brain.mesh;
  const std::vector<int>& fixed = brain.fixed_nodes;
  std::printf("split sub-model: %zu nodes, %zu tetrahedra, %zu clamped, %zu pressed\n",
              m.num_vertices(), m.num_tets(), fixed.size(), patch.size());
  ASSERT_GE(patch.size(), 3u);
  Material mat = brain.material;
  mat.poisson_ratio = 0.49;
  mat.element = Element::kSmoothedTet;
  const std::string what = element_name(mat.element);
  PrescribedDofs pressed;
  pressed.nodes = patch;
  pressed.displacement_m = Eigen::Vector3d(0.0, 0.0, -0.010);
  EquilibriumSolver solver({&m, MaterialMap::uniform(mat), Tier::kNonlinear, fixed,
                            {pressed}, {}});
  NewtonOptions o;
  o.tangent_predictor = true;
  o.max_iterations = 16;
  o.max_cutbacks = 4;
  EquilibriumResult r;
  ASSERT_NO_THROW(r = solver.solve(Eigen::VectorXd(), o)) << what;
  ASSERT_TRUE(r.displacement_m.allFinite()) << what;
  double force = 0.0;
  for (int v : patch) force -= r.reaction_n[3 * v + 2];
  const std::vector<double>& res = r.increments.back().residual_n;
  std::printf("%s: patch force %.6f N, %zu increments, %d clamped, %d inverted elements, %d held "
              "by the element barrier; last increment:", what.c_str(), force, r.increments.size(),
              r.elements.clamped_elements, r.elements.inverted_elements,
              r.elements.barrier_elements);
  for (double x : res) std::printf(" %.2e", x);
  std::printf(" N\n");
  EXPECT_GT(r.elements.barrier_elements, 0) << what;
  EXPECT_EQ(r.elements.inverted_elements, 0) << what;
  ASSERT_GE(res.size(), 3u) << what;
  EXPECT_LE(res.back(), 1e-10 * r.force_scale_n) << what;
  EXPECT_LE(res.size(), 16u) << what;
  const std::size_t n = res.size();
  EXPECT_LT(res[n - 1] / res[n - 2], 0.1) << what;
  std::filesystem::remove_all(dir);
}

// F(h) = F* + C h^p sampled at h, h/2, h/4 gives back F* and p (p = 1, 1.5, 2; from above and
// from below); forces that stop falling, turn, or fall at order < 0.3 have no limit, and say why.
TEST(Richardson, RecoversAPowerLawAndRefusesNoAsymptoticRange) {
  for (const double p : {1.0, 1.5, 2.0})
    for (const double c : {0.4, -0.2}) {
      auto f = [&](double h) { return 0.15 + c * std::pow(h, p); };
      const bench::Limit l = bench::richardson(f(1.0), f(0.5), f(0.25));
      EXPECT_NEAR(l.order, p, 1e-12) << "p " << p << " C " << c;
      EXPECT_NEAR(l.force_n, 0.15, 1e-14) << "p " << p << " C " << c;
      EXPECT_TRUE(l.why.empty());
    }
  EXPECT_EQ(bench::richardson(0.2, 0.18, 0.18).why, "the differences vanish or change sign");
  EXPECT_EQ(bench::richardson(0.2, 0.18, 0.19).why, "the differences vanish or change sign");
  EXPECT_EQ(bench::richardson(0.2, 0.18, 0.1615).why, "order below 0.3");  // p = 0.2
  EXPECT_EQ(bench::richardson(0.2, std::nan(""), 0.1).why, "a mesh missing");
  EXPECT_TRUE(std::isnan(bench::richardson(0.2, 0.18, 0.18).force_n));
  // The converged answer: C3D10's limit when it has one, else smoothed-tet's, else none.
  const bench::Limit c3 = bench::richardson(0.2, 0.17, 0.16);
  const bench::Limit st = bench::richardson(0.19, 0.165, 0.155);
  const bench::Limit none = bench::richardson(0.2, 0.18, 0.18);
  EXPECT_EQ(bench::converged_answer(c3, st).force_n, c3.force_n);
  EXPECT_STREQ(bench::converged_answer(c3, st).by, "C3D10's limit");
  EXPECT_EQ(bench::converged_answer(none, st).force_n, st.force_n);
  EXPECT_STREQ(bench::converged_answer(none, st).by, "smoothed-tet's limit");
  EXPECT_TRUE(std::isnan(bench::converged_answer(none, none).force_n));
}

}  // namespace
}  // namespace neurosim::fem
