// neurosim-model: meshes valid, quality reported, artery inside the brain, scene loads.
#include "tools/model/model.hpp"
#include "server/mesh/io.hpp"
#include "server/mesh/quality.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <utility>

namespace {

using neurosim::mesh::TetMesh;
using neurosim::mesh::Vec3;
namespace model = neurosim::model;
namespace scene = neurosim::scene;
using neurosim::testing::slurp;

const char* kMri = "/usr/share/mricron/templates/ch2bet.nii.gz";

// Coarse (quick) versions of the real model: same pipeline, bigger cells.
model::ModelOptions coarse_options(const std::filesystem::path& dir) {
  model::ModelOptions o;
  o.mri_path = kMri;
  o.out_dir = dir;
  o.brain_cell_size_mm = 12.0;  // ~1.2k vertices; the artery keeps its default (a coarser
                                // tube takes the perturber longer, not shorter)
  o.seed = 7;
  return o;
}

// Independent of the builder's own check: is p inside (or on) some tetrahedron of `host`?
bool in_some_tet(const TetMesh& host, const Vec3& p) {
  for (std::size_t t = 0; t < host.num_tets(); ++t) {
    const auto& tet = host.tets()[t];
    const Vec3& a = host.vertices()[tet[0]];
    const Vec3& b = host.vertices()[tet[1]];
    const Vec3& c = host.vertices()[tet[2]];
    const Vec3& d = host.vertices()[tet[3]];
    const Vec3 lo = a.cwiseMin(b).cwiseMin(c).cwiseMin(d);
    const Vec3 hi = a.cwiseMax(b).cwiseMax(c).cwiseMax(d);
    if ((p.array() < lo.array()).any() || (p.array() > hi.array()).any()) continue;
    Eigen::Matrix3d m;
    m << b - a, c - a, d - a;
    const Vec3 l = m.partialPivLu().solve(p - a);
    if (l.minCoeff() >= -1e-12 && l.sum() <= 1.0 + 1e-12) return true;
  }
  return false;
}

int artery_vertices_outside(const TetMesh& brain, const TetMesh& artery) {
  int outside = 0;
  for (const Vec3& x : artery.vertices()) outside += in_some_tet(brain, x) ? 0 : 1;
  return outside;
}


class ModelTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!std::filesystem::exists(kMri)) return;
    dir_ = neurosim::testing::temp_dir("model");
    result_ = std::make_unique<model::ModelResult>(model::build_model(coarse_options(dir_)));
  }
  static void TearDownTestSuite() {
    if (!dir_.empty()) std::filesystem::remove_all(dir_);
  }
  void SetUp() override {
    if (!result_) GTEST_SKIP() << kMri << " missing (Debian package mricron-data)";
  }
  static std::filesystem::path dir_;
  static std::unique_ptr<model::ModelResult> result_;
};
std::filesystem::path ModelTest::dir_;
std::unique_ptr<model::ModelResult> ModelTest::result_;
// ctest names start with model_ (the suite name).
using model_builder = ModelTest;

TEST_F(model_builder, MeshesHaveNoInvertedElements) {
  for (const auto* m : {&result_->brain, &result_->artery}) {
    const auto data = neurosim::mesh::read_medit(m->file.string(), 1e-3);
    const auto q = neurosim::mesh::quality(data.vertices_m, data.tets);
    EXPECT_EQ(q.inverted, 0) << m->file;
    EXPECT_EQ(q.zero_volume, 0) << m->file;
    EXPECT_GT(q.num_tets, 100) << m->file;
    const TetMesh built = neurosim::mesh::load_tet_mesh(m->file.string(), 1e-3);
    EXPECT_EQ(built.inverted_fixed(), 0) << m->file;
    EXPECT_EQ(static_cast<int>(built.num_tets()), m->tets);
    EXPECT_EQ(static_cast<int>(built.num_vertices()), m->vertices);
  }
}

TEST_F(model_builder, MinimumDihedralAngleIsReported) {
  for (const auto* m : {&result_->brain, &result_->artery}) {
    const TetMesh built = neurosim::mesh::load_tet_mesh(m->file.string(), 1e-3);
    const auto q = neurosim::mesh::quality(built);
    EXPECT_NEAR(m->quality.min_dihedral_deg, q.min_dihedral_deg, 1e-9) << m->file;
    EXPECT_GT(q.min_dihedral_deg, 0.0);
    EXPECT_LT(q.min_dihedral_deg, 70.53);
  }
  const std::string text = model::summary(*result_);
  EXPECT_NE(text.find("min dihedral"), std::string::npos) << text;
  EXPECT_NE(text.find("paper 5367"), std::string::npos) << text;
  EXPECT_NE(text.find("paper 1644"), std::string::npos) << text;
}

TEST_F(model_builder, ArteryLiesInsideTheBrain) {
  const TetMesh brain = neurosim::mesh::load_tet_mesh(result_->brain.file.string(), 1e-3);
  const TetMesh artery = neurosim::mesh::load_tet_mesh(result_->artery.file.string(), 1e-3);
  EXPECT_EQ(result_->artery_vertices_outside, 0);
  EXPECT_EQ(artery_vertices_outside(brain, artery), 0);
  // The check itself can fail: shifted 0.2 m away the artery is outside.
  std::vector<Vec3> moved = artery.vertices();
  for (auto& x : moved) x.x() += 0.2;
  const TetMesh shifted = TetMesh::build(moved, artery.tets());
  EXPECT_EQ(artery_vertices_outside(brain, shifted), static_cast<int>(shifted.num_vertices()));
}

TEST_F(model_builder, SceneParsesAndLoads) {
  const scene::Scene s = scene::read_scene(result_->scene);
  ASSERT_EQ(s.meshes_size(), 2);
  const int b = scene::find_mesh(s, "brain"), a = scene::find_mesh(s, "artery");
  ASSERT_GE(b, 0);
  ASSERT_GE(a, 0);
  EXPECT_GT(s.meshes(a).priority(), s.meshes(b).priority());
  EXPECT_NE(s.meshes(a).provenance().find("generated"), std::string::npos);
  EXPECT_DOUBLE_EQ(s.meshes(b).file_unit_m(), 1e-3);
  EXPECT_DOUBLE_EQ(s.meshes(b).material().youngs_modulus_pa(), 3e3);
  EXPECT_DOUBLE_EQ(s.meshes(a).material().youngs_modulus_pa(), 1e6);
  EXPECT_FALSE(s.meshes(b).material().source().empty());
  ASSERT_EQ(s.couplings_size(), 1);
  EXPECT_EQ(s.couplings(0).host(), "brain");
  EXPECT_EQ(s.couplings(0).embedded(), "artery");
  EXPECT_EQ(s.couplings(0).kind(), scene::Coupling::TIE);
  EXPECT_EQ(s.image().file(), kMri);
  EXPECT_DOUBLE_EQ(s.image().file_unit_m(), 1e-3);
  EXPECT_EQ(s.tools_size(), 1);

  const auto brain = scene::load_mesh(s.meshes(b), result_->scene.parent_path(), "test");
  const auto artery = scene::load_mesh(s.meshes(a), result_->scene.parent_path(), "test");
  EXPECT_EQ(static_cast<int>(brain.mesh.num_vertices()), result_->brain.vertices);
  EXPECT_EQ(static_cast<int>(artery.mesh.num_tets()), result_->artery.tets);
  // Fixed nodes: a basal layer, neither none nor the whole brain, all at the bottom.
  ASSERT_FALSE(brain.fixed_nodes.empty());
  EXPECT_LT(brain.fixed_nodes.size(), brain.mesh.num_vertices() / 4);
  Vec3 lo, hi;
  brain.mesh.bounds(lo, hi);
  for (int n : brain.fixed_nodes) {
    EXPECT_LT(brain.mesh.vertices()[n].z(), lo.z() + 0.5 * (hi.z() - lo.z())) << "node " << n;
  }
  // The static load case pushes a few brain surface nodes.
  ASSERT_EQ(s.prescribed_size(), 1);
  EXPECT_EQ(s.prescribed(0).mesh(), "brain");
  const auto pushed = scene::select_nodes(brain.mesh, s.prescribed(0).region(), "prescribed");
  EXPECT_EQ(static_cast<int>(pushed.size()), result_->prescribed_nodes);
  EXPECT_LT(pushed.size(), 50u);
  // The server's loader (carving, tie, factorization) takes it.
  EXPECT_NO_THROW(neurosim::interaction::Simulation::build(scene::load_model(result_->scene)));
  // Brain-sized (m): Colin27 is about 0.14 x 0.17 x 0.12 m.
  EXPECT_GT((hi - lo).minCoeff(), 0.08);
  EXPECT_LT((hi - lo).maxCoeff(), 0.25);
}

TEST_F(model_builder, SameSeedSameFilesAndPaperMaterial) {
  const auto dir = neurosim::testing::temp_dir("model_again");
  auto o = coarse_options(dir);
  o.material = model::MaterialSet::Paper;
  const auto again = model::build_model(o);
  EXPECT_EQ(slurp(again.brain.file), slurp(result_->brain.file));
  EXPECT_EQ(slurp(again.artery.file), slurp(result_->artery.file));
  const scene::Scene s = scene::read_scene(again.scene);
  for (const auto& m : s.meshes()) {
    EXPECT_DOUBLE_EQ(m.material().youngs_modulus_pa(), 1e6) << m.id();
    EXPECT_DOUBLE_EQ(m.material().poisson_ratio(), 0.4) << m.id();
    EXPECT_NE(m.material().source().find("paper"), std::string::npos) << m.id();
  }
  std::filesystem::remove_all(dir);
}

TEST(model_options, ArteryCourseOutsideTheBrainAndBadInputsAreRefused) {
  if (!std::filesystem::exists(kMri)) GTEST_SKIP() << kMri << " missing";
  const auto dir = neurosim::testing::temp_dir("model_bad");
  auto o = coarse_options(dir);
  // MNI x = 85 mm is beyond the right side of the brain.
  o.artery_course_world_mm = {{40, 0, 0}, {85, 0, 0}};
  EXPECT_THROW(model::build_model(o), std::runtime_error);
  o.artery_course_world_mm.clear();
  o.brain_cell_size_mm = -1.0;
  EXPECT_THROW(model::build_model(o), std::invalid_argument);
  o.brain_cell_size_mm = 12.0;
  o.mri_path = (dir / "missing.nii.gz").string();
  EXPECT_THROW(model::build_model(o), std::runtime_error);
  std::filesystem::remove_all(dir);
}

// Mean length of the edges whose midpoint lies between from_mm and to_mm of centre_mm (image
// mm), and how many there are.
std::pair<double, int> mean_edge(const TetMesh& mesh, const Vec3& centre_mm, double from_mm, double to_mm) {
  double sum = 0.0;
  int n = 0;
  for (const auto& t : mesh.tets())
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const Vec3 p = 1e3 * mesh.vertices()[t[a]], q = 1e3 * mesh.vertices()[t[b]];
        const double r = (0.5 * (p + q) - centre_mm).norm();
        if (r < from_mm || r > to_mm) continue;
        sum += (p - q).norm();  // each interior edge counted once per tetrahedron: a weighted mean
        ++n;
      }
  return {n > 0 ? sum / n : 0.0, n};
}

TEST(model_refinement, SizeFieldGradesFromTheCentreToTheMeshSize) {
  model::LocalRefinement r;
  EXPECT_FALSE(r.on());
  EXPECT_EQ(r.size_at(Vec3(1, 2, 3), 7.0), 7.0);
  r.centre_mm = Vec3(10, 0, 0);
  r.cell_size_mm = 0.5;
  r.radius_mm = 3.0;
  r.grading = 0.25;
  EXPECT_TRUE(r.on());
  EXPECT_DOUBLE_EQ(r.size_at(Vec3(10, 0, 0), 7.0), 0.5);
  EXPECT_DOUBLE_EQ(r.size_at(Vec3(10, 3, 0), 7.0), 0.5);
  EXPECT_DOUBLE_EQ(r.size_at(Vec3(10, 0, 7), 7.0), 0.5 + 0.25 * 4.0);
  EXPECT_DOUBLE_EQ(r.size_at(Vec3(100, 0, 0), 7.0), 7.0);  // capped at the mesh's own size
  EXPECT_NO_THROW(r.check(7.0));
}

TEST(model_refinement, BadValuesAreRefusedNamingTheOption) {
  auto refused = [](model::LocalRefinement r, const char* option) {
    try {
      r.check(7.0);
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(option), std::string::npos) << e.what();
      return;
    }
    ADD_FAILURE() << "not refused: " << option;
  };
  model::LocalRefinement ok;
  ok.cell_size_mm = 1.0;
  auto r = ok;
  r.cell_size_mm = 7.0;  // not below the mesh's size
  refused(r, "--refine-cell-size");
  r.cell_size_mm = -1.0;
  refused(r, "--refine-cell-size");
  r = ok;
  r.radius_mm = -1.0;
  refused(r, "--refine-radius");
  r = ok;
  r.grading = 0.0;
  refused(r, "--refine-grading");
  r = ok;
  r.centre_mm.x() = std::nan("");
  refused(r, "--refine-at");
  if (!std::filesystem::exists(kMri)) GTEST_SKIP() << kMri << " missing";
  const auto dir = neurosim::testing::temp_dir("model_refine_bad");
  auto o = coarse_options(dir);
  o.brain_refinement.cell_size_mm = 20.0;  // coarser than the 12 mm brain
  EXPECT_THROW(model::build_model(o), std::invalid_argument);
  // A point far outside the brain refines nothing: refused after meshing, naming the option.
  o.brain_refinement.cell_size_mm = 3.0;
  o.brain_refinement.centre_mm = Vec3(-500.0, -500.0, -500.0);
  try {
    model::build_model(o);
    ADD_FAILURE() << "a refinement point 500 mm outside the brain was not refused";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("--refine-at"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The coarse brain meshed again with 3 mm cells within 4 mm of its highest vertex: the cells
// there shrink (mean edge near the point well below the unrefined mesh's), the mesh stays valid,
// and away from the point it is the coarse brain's size (the vertex count grows by a local
// amount only).
TEST_F(model_builder, LocalRefinementShrinksTheCellsAroundItsPointOnly) {
  const TetMesh coarse = neurosim::mesh::load_tet_mesh(result_->brain.file.string(), 1e-3);
  Vec3 top = coarse.vertices().front();
  for (const Vec3& x : coarse.vertices())
    if (x.z() > top.z()) top = x;
  const Vec3 centre_mm = 1e3 * top;
  const auto dir = neurosim::testing::temp_dir("model_refine");
  auto o = coarse_options(dir);
  o.brain_refinement.centre_mm = centre_mm;
  o.brain_refinement.cell_size_mm = 3.0;
  o.brain_refinement.radius_mm = 4.0;
  o.brain_refinement.grading = 0.5;
  const model::ModelResult refined = model::build_model(o);
  const TetMesh fine = neurosim::mesh::load_tet_mesh(refined.brain.file.string(), 1e-3);
  EXPECT_EQ(neurosim::mesh::quality(fine).inverted, 0);
  const auto [coarse_edge, coarse_n] = mean_edge(coarse, centre_mm, 0.0, 6.0);
  const auto [fine_edge, fine_n] = mean_edge(fine, centre_mm, 0.0, 6.0);
  EXPECT_LT(fine_edge, 0.6 * coarse_edge) << coarse_n << " / " << fine_n << " edges";
  EXPECT_LT(fine_edge, 2.0 * o.brain_refinement.cell_size_mm);
  EXPECT_GT(fine.num_vertices(), coarse.num_vertices());
  EXPECT_LT(fine.num_vertices(), coarse.num_vertices() + 2000);
  // Away from the point (beyond radius + (12 - 3) / grading = 22 mm) the cells are the coarse
  // brain's: the same mean edge within 15 % far from the point.
  const double far_mm = 40.0, everywhere_mm = 1e6;
  EXPECT_NEAR(mean_edge(fine, centre_mm, far_mm, everywhere_mm).first /
                  mean_edge(coarse, centre_mm, far_mm, everywhere_mm).first,
              1.0, 0.15);
  const std::string text = slurp(refined.scene);
  EXPECT_NE(text.find("--refine-cell-size 3"), std::string::npos) << "the scene's text names the refinement";
  std::filesystem::remove_all(dir);
}

// The committed/generated full-size scene, when present.
TEST(model_scene, BrainArterySceneLoadsWithArteryInside) {
  const auto path = neurosim::testing::source_dir() / "scenes" / "brain_artery.scene";
  if (!std::filesystem::exists(path)) GTEST_SKIP() << path << " not built (run neurosim-model)";
  const scene::Scene s = scene::read_scene(path);
  const auto brain =
      scene::load_mesh(s.meshes(scene::find_mesh(s, "brain")), path.parent_path(), path.string());
  const auto artery =
      scene::load_mesh(s.meshes(scene::find_mesh(s, "artery")), path.parent_path(), path.string());
  EXPECT_EQ(brain.mesh.inverted_fixed(), 0);
  EXPECT_EQ(artery.mesh.inverted_fixed(), 0);
  EXPECT_GT(neurosim::mesh::quality(brain.mesh).min_dihedral_deg, 0.0);
  EXPECT_FALSE(brain.fixed_nodes.empty());
  EXPECT_EQ(artery_vertices_outside(brain.mesh, artery.mesh), 0);
}

}  // namespace
