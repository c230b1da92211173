// The builder's load check: parts of the (carved) brain that no fixed node holds are found and
// pinned, and the scenes it writes at several cell sizes and seeds load in the server's
// simulation (carving, tie, factorization).
#include "tools/model/islands.hpp"
#include "tools/model/model.hpp"
#include "server/fem/static_solver.hpp"
#include "server/interaction/simulation.hpp"
#include "server/mesh/generate.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "scene.pb.h"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>

namespace {

using neurosim::mesh::TetMesh;
using neurosim::mesh::Vec3;
namespace model = neurosim::model;
namespace fem = neurosim::fem;

const char* kMri = "/usr/share/mricron/templates/ch2bet.nii.gz";

TetMesh box(const Vec3& lo, const Vec3& hi) {
  neurosim::mesh::MeshingOptions o;
  o.cell_size_m = 0.006;
  o.seed = 3;
  return neurosim::mesh::generate_box(lo, hi, o).mesh;
}

// Two boxes in one mesh, 1 cm apart; only the first touches the fixed plane z = 0.
struct TwoBoxes {
  TetMesh mesh;
  int first_box_nodes{0};
  std::vector<int> fixed;
};
TwoBoxes two_boxes() {
  const TetMesh a = box(Vec3(0, 0, 0), Vec3(0.02, 0.02, 0.02));
  const TetMesh b = box(Vec3(0.03, 0, 0.005), Vec3(0.05, 0.02, 0.025));
  std::vector<Vec3> x = a.vertices();
  x.insert(x.end(), b.vertices().begin(), b.vertices().end());
  std::vector<neurosim::mesh::Tet> t = a.tets();
  const int off = static_cast<int>(a.num_vertices());
  for (auto tet : b.tets()) {
    for (int& v : tet) v += off;
    t.push_back(tet);
  }
  TwoBoxes out;
  out.mesh = TetMesh::build(x, t);
  out.first_box_nodes = off;
  for (int v = 0; v < static_cast<int>(x.size()); ++v)
    if (x[v].z() <= 1e-12) out.fixed.push_back(v);
  return out;
}

fem::MaterialMap soft() {
  fem::Material m;
  m.youngs_modulus_pa = 3e3;
  m.poisson_ratio = 0.45;
  return fem::MaterialMap::uniform(m);
}

TEST(model_islands, APartWithoutFixedNodesIsFoundAndPinnedSoTheStiffnessFactorizes) {
  const TwoBoxes s = two_boxes();
  ASSERT_FALSE(s.fixed.empty());
  const model::IslandReport r = model::find_islands(s.mesh, s.fixed, {}, "two boxes", 0.9);
  EXPECT_EQ(r.carved_tets, 0);
  ASSERT_EQ(r.part_nodes.size(), 1u);
  const int second = static_cast<int>(s.mesh.num_vertices()) - s.first_box_nodes;
  EXPECT_EQ(r.part_nodes[0], second);
  ASSERT_EQ(static_cast<int>(r.pinned_nodes.size()), second);
  EXPECT_EQ(r.pinned_nodes.front(), s.first_box_nodes);
  // The judge is CHOLMOD, not the rule the builder uses: without the pins the stiffness is
  // singular, with them it factorizes.
  fem::SolverOptions no_rule;
  no_rule.check_rigid_modes = false;
  EXPECT_ANY_THROW(fem::StaticSolver(s.mesh, soft(), s.fixed, no_rule));
  std::vector<int> pinned = s.fixed;
  pinned.insert(pinned.end(), r.pinned_nodes.begin(), r.pinned_nodes.end());
  EXPECT_NO_THROW(fem::StaticSolver(s.mesh, soft(), pinned, no_rule));
  // A "part" that large is not an island: refused, not pinned.
  EXPECT_THROW(model::find_islands(s.mesh, s.fixed, {}, "two boxes", 0.05), std::runtime_error);
}

// Two tetrahedra sharing one edge: joined by nodes, yet the second turns about the edge.
TEST(model_islands, APartHangingOnOneEdgeIsPinned) {
  const std::vector<Vec3> x{{0, 0, 0}, {0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01},
                            {0.005, -0.01, 0.003}, {0.004, -0.003, -0.01}};
  const TetMesh m = TetMesh::build(x, {{0, 1, 2, 3}, {0, 1, 4, 5}});
  const std::vector<int> fixed{0, 1, 2, 3};
  const model::IslandReport r = model::find_islands(m, fixed, {}, "hinge", 0.9);
  ASSERT_EQ(r.part_nodes.size(), 1u);
  EXPECT_EQ(r.pinned_nodes, (std::vector<int>{0, 1, 4, 5}));
  fem::SolverOptions no_rule;
  no_rule.check_rigid_modes = false;
  EXPECT_ANY_THROW(fem::StaticSolver(m, soft(), fixed, no_rule));
  EXPECT_NO_THROW(fem::StaticSolver(m, soft(), {0, 1, 2, 3, 4, 5}, no_rule));
}

// A part is held by 3 non-collinear nodes, its own fixed ones or shared with a held part: the
// hinged tetrahedron with one more fixed node is not pinned (and CHOLMOD agrees).
TEST(model_islands, APartSharingThreeNodesWithAHeldPartIsNotPinned) {
  const std::vector<Vec3> x{{0, 0, 0}, {0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01},
                            {0.005, -0.01, 0.003}, {0.004, -0.003, -0.01}, {-0.01, 0.004, -0.004}};
  // Tets 0 and 2 share a face (one part); tet 1 shares only the edge {0, 1} with them.
  const TetMesh hinge = TetMesh::build(x, {{0, 1, 2, 3}, {0, 1, 4, 5}, {0, 2, 3, 6}});
  const std::vector<int> fixed{0, 1, 2, 3};
  EXPECT_EQ(model::find_islands(hinge, fixed, {}, "hinge", 0.9).pinned_nodes.size(), 4u);
  // Node 4 fixed as well: tet 1 holds 0, 1 (shared) and 4 (fixed), non-collinear.
  const std::vector<int> more{0, 1, 2, 3, 4};
  EXPECT_TRUE(model::find_islands(hinge, more, {}, "hinge", 0.9).pinned_nodes.empty());
  fem::SolverOptions no_rule;
  no_rule.check_rigid_modes = false;
  EXPECT_NO_THROW(fem::StaticSolver(hinge, soft(), more, no_rule));
  EXPECT_ANY_THROW(fem::StaticSolver(hinge, soft(), fixed, no_rule));
}

TEST(model_islands, CarvingAroundAnEmbeddedMeshCountsTheCarvedTetrahedra) {
  const TetMesh host = box(Vec3(0, 0, 0), Vec3(0.04, 0.04, 0.04));
  const TetMesh inner = box(Vec3(0.012, 0.012, 0.012), Vec3(0.028, 0.028, 0.028));
  std::vector<int> fixed;
  for (int v = 0; v < static_cast<int>(host.num_vertices()); ++v)
    if (host.vertices()[v].z() <= 1e-12) fixed.push_back(v);
  const model::IslandReport r = model::find_islands(host, fixed, {&inner}, "box in box");
  EXPECT_GT(r.carved_tets, 0);
  EXPECT_LT(r.carved_tets, static_cast<int>(host.num_tets()));
  EXPECT_TRUE(r.pinned_nodes.empty());
}

// A real build (coarse, so seconds; model_test builds 12 mm, seed 7, and loads it the same way):
// the scene written loads in the server's simulation.
TEST(model_islands, SceneBuiltAtAnotherCellSizeAndSeedLoads) {
  if (!std::filesystem::exists(kMri)) GTEST_SKIP() << kMri << " missing (mricron-data)";
  const auto dir = neurosim::testing::temp_dir("model_islands");
  struct Case {
    double cell_mm;
    std::uint32_t seed;
  };
  for (const Case c : {Case{14.0, 2}}) {
    SCOPED_TRACE("cell " + std::to_string(c.cell_mm) + " mm, seed " + std::to_string(c.seed));
    model::ModelOptions o;
    o.mri_path = kMri;
    o.out_dir = dir;
    o.name = "c" + std::to_string(static_cast<int>(c.cell_mm)) + "s" + std::to_string(c.seed);
    o.brain_cell_size_mm = c.cell_mm;
    o.seed = c.seed;
    const model::ModelResult r = model::build_model(o);
    EXPECT_GT(r.carved_tets, 0);
    const auto m = neurosim::scene::load_model(r.scene);
    EXPECT_NO_THROW(neurosim::interaction::Simulation::build(m));
    // A 4-node part of this one hangs on the rest by two edges (held: not pinned).
    EXPECT_EQ(r.pinned_nodes, 0);
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
