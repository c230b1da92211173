// Rigid meshes (closed triangle surfaces with openings) and tissues (named labels with their own
// materials): parsing, validation, refusal of an open surface naming the file, and per-tetrahedron
// materials in the compiled Model (stiffness against an element-by-element hand assembly).
#include "server/fem/assembly.hpp"
#include "server/fem/tet_element.hpp"
#include "server/mesh/io.hpp"
#include "server/scene/compile.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace neurosim::scene {
namespace {

using testing::message_of;

// The unit tetrahedron's surface (mm), outward; `drop` removes one face (an open surface).
void write_tet_surface(const std::filesystem::path& file, bool drop = false, bool inward = false) {
  std::ofstream out(file);
  out << "MeshVersionFormatted 1\nDimension 3\nVertices\n4\n0 0 0 0\n10 0 0 0\n0 10 0 0\n0 0 10 0\n"
      << "Triangles\n"
      << (drop ? 3 : 4) << "\n";
  const char* faces[4] = {"1 3 2", "1 2 4", "1 4 3", "2 3 4"};
  const char* flipped[4] = {"1 2 3", "1 4 2", "1 3 4", "2 4 3"};
  for (int f = 0; f < (drop ? 3 : 4); ++f) out << (inward ? flipped[f] : faces[f]) << " 1\n";
  out << "End\n";
}

// Two tetrahedra sharing the face (1,2,3), labels 1 and 2 (mm).
void write_two_tets(const std::filesystem::path& file, int second_label = 2) {
  std::ofstream out(file);
  out << "MeshVersionFormatted 1\nDimension 3\nVertices\n5\n0 0 0 0\n10 0 0 0\n0 10 0 0\n"
         "0 0 10 0\n0 0 -10 0\nTetrahedra\n2\n1 2 3 4 1\n1 3 2 5 "
      << second_label << "\nEnd\n";
}

std::string brain_entry(const std::string& extra) {
  return R"(
meshes {
  id: "brain"
  file: "two.mesh"
  file_unit_m: 0.001
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 source: "mesh" element: "linear-tet" }
  )" + extra +
         "\n}\n";
}

std::string skull_entry(const std::string& file, const std::string& extra = "") {
  return R"(
meshes {
  id: "skull"
  file: ")" +
         file + R"("
  file_unit_m: 0.001
  rigid: true
  provenance: "test"
  openings { center_m { x: 0.002 y: 0.002 z: 0.0 } axis { z: -2 } radius_m: 0.001 half_length_m: 0.005 provenance: "test" }
  )" + extra +
         "\n}\n";
}

class RigidTissue : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::temp_dir("rigid_tissue");
    write_tet_surface(dir_ / "closed.mesh");
    write_tet_surface(dir_ / "open.mesh", true);
    write_tet_surface(dir_ / "inward.mesh", false, true);
    write_two_tets(dir_ / "two.mesh");
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  Model compile_text(const std::string& text) {
    const std::string source = (dir_ / "t.scene").string();
    return compile(parse_scene(text, source), source);
  }
  std::string refusal(const std::string& text) {
    return message_of([&] { compile_text(text); });
  }
  std::filesystem::path dir_;
};

TEST_F(RigidTissue, ClosedRigidSurfaceCompilesOutsideTheFemMeshes) {
  const Model m = compile_text(brain_entry("") + skull_entry("closed.mesh"));
  ASSERT_EQ(m.meshes.size(), 1u);  // the rigid mesh is not a body
  ASSERT_EQ(m.rigid.size(), 1u);
  const RigidSurface& s = m.rigid[0];
  EXPECT_EQ(s.id, "skull");
  EXPECT_EQ(s.vertices_m.size(), 4u);
  EXPECT_EQ(s.triangles.size(), 4u);
  EXPECT_NEAR(s.vertices_m[1].x(), 0.010, 1e-15);  // file_unit_m applied
  EXPECT_NEAR(s.enclosed_volume_m3, 1e-6 / 6.0, 1e-15);
  ASSERT_EQ(s.openings.size(), 1u);
  EXPECT_NEAR(s.openings[0].axis.z(), -1.0, 1e-15);  // normalised
  EXPECT_NEAR(s.openings[0].radius_m, 0.001, 1e-15);
  EXPECT_TRUE(s.openings[0].contains(mesh::Vec3(0.002, 0.0025, 0.004)));
  EXPECT_FALSE(s.openings[0].contains(mesh::Vec3(0.002, 0.0035, 0.0)));    // outside the radius
  EXPECT_FALSE(s.openings[0].contains(mesh::Vec3(0.002, 0.002, 0.0051)));  // beyond the length
}

TEST_F(RigidTissue, SceneWithoutRigidMeshHasNone) {
  const Model m = compile_text(brain_entry(""));
  EXPECT_TRUE(m.rigid.empty());
  EXPECT_TRUE(m.meshes[0].materials.tet_material.empty());  // uniform
  EXPECT_TRUE(m.meshes[0].tissues.empty());
}

TEST_F(RigidTissue, OpenRigidSurfaceRefusedNamingTheFile) {
  const std::string e = refusal(brain_entry("") + skull_entry("open.mesh"));
  EXPECT_NE(e.find("open.mesh"), std::string::npos) << e;
  EXPECT_NE(e.find("not a closed"), std::string::npos) << e;
  EXPECT_NE(e.find("3 boundary"), std::string::npos) << e;
  EXPECT_NE(e.find("\"skull\""), std::string::npos) << e;
}

TEST_F(RigidTissue, InwardRigidSurfaceRefused) {
  const std::string e = refusal(brain_entry("") + skull_entry("inward.mesh"));
  EXPECT_NE(e.find("inward.mesh"), std::string::npos) << e;
  EXPECT_NE(e.find("face inward"), std::string::npos) << e;
}

TEST_F(RigidTissue, RigidMeshValidation) {
  auto check = [&](const std::string& text, const std::string& field) {
    const std::string e = message_of([&] { parse_scene(text, "v.scene"); });
    EXPECT_NE(e.find(field), std::string::npos) << "expected " << field << " in: " << e;
  };
  check(brain_entry("") +
            skull_entry("closed.mesh", "material { youngs_modulus_pa: 1e9 poisson_ratio: 0.3 }"),
        "meshes[1].material: a rigid mesh has no material");
  check(brain_entry("") + skull_entry("closed.mesh", "fixed { box { min_m {} max_m {} } }"),
        "meshes[1].fixed");
  check(brain_entry("") + skull_entry("closed.mesh", "tissues { label: 1 name: \"x\" }"),
        "meshes[1].tissues");
  check(brain_entry("openings { axis { z: 1 } radius_m: 0.01 half_length_m: 0.01 }"),
        "meshes[0].openings: only rigid meshes have openings");
  check(skull_entry("closed.mesh"), "every mesh is rigid");
  check(brain_entry("") + skull_entry("closed.mesh") +
            "loads { mesh: \"skull\" region { nodes { ids: 0 } } }",
        "loads[0].mesh: mesh \"skull\" is rigid");
  check(brain_entry("") + skull_entry("closed.mesh") +
            "couplings { host: \"brain\" embedded: \"skull\" }",
        "couplings[0].embedded: mesh \"skull\" is rigid");
  const std::string bad_opening = R"(
meshes { id: "skull" file: "closed.mesh" rigid: true
  openings { axis { z: 0 } radius_m: 0.01 half_length_m: 0.01 } })";
  check(brain_entry("") + bad_opening, "meshes[1].openings[0].axis: must be non-zero");
  const std::string wide = R"(
meshes { id: "skull" file: "closed.mesh" rigid: true
  openings { axis { z: 1 } radius_m: 0.5 half_length_m: 0.01 } })";
  check(brain_entry("") + wide, "meshes[1].openings[0].radius_m: 0.5 is outside [0, 0.1]");
  check(brain_entry("tissues { label: 1 name: \"a\" } tissues { label: 1 name: \"b\" }"),
        "meshes[0].tissues[1].label: label 1 listed twice");
  check(brain_entry("tissues { label: 1 name: \"a\" } tissues { label: 2 name: \"a\" }"),
        "meshes[0].tissues[1].name: duplicate name");
  check(brain_entry("tissues { label: 1 }"), "meshes[0].tissues[0].name: missing");
  check(brain_entry("tissues { label: 2 name: \"b\" material { youngs_modulus_pa: 3000 "
                    "poisson_ratio: 0.5 } }"),
        "meshes[0].tissues[0].material.poisson_ratio");
  // The element: a known name, one per mesh.
  check(brain_entry("tissues { label: 2 name: \"b\" material { youngs_modulus_pa: 3000 "
                    "poisson_ratio: 0.45 element: \"anp-tet\" } }"),
        "meshes[0].tissues[0].material.element: \"anp-tet\" differs from the mesh's element");
  check(brain_entry("tissues { label: 2 name: \"b\" material { youngs_modulus_pa: 3000 "
                    "poisson_ratio: 0.45 element: \"C3D10\" } }"),
        "meshes[0].tissues[0].material.element: unknown element \"C3D10\" (known: anp-tet, linear-tet, smoothed-tet)");
}

TEST_F(RigidTissue, TissueMaterialsPerTetrahedron) {
  const Model m = compile_text(brain_entry(R"(
  tissues { label: 1 name: "cerebrum" provenance: "atlas" }
  tissues { label: 2 name: "cerebellum" material { name: "soft" youngs_modulus_pa: 1500 poisson_ratio: 0.4 source: "cited" } })"));
  const LoadedMesh& lm = m.meshes[0];
  ASSERT_EQ(lm.tissues.size(), 2u);
  EXPECT_EQ(lm.tissues[0].name, "cerebrum");
  EXPECT_FALSE(lm.tissues[0].own_material);
  EXPECT_EQ(lm.tissues[0].material.youngs_modulus_pa, 3000.0);
  EXPECT_TRUE(lm.tissues[1].own_material);
  EXPECT_EQ(lm.tissues[1].material_source, "cited");
  ASSERT_EQ(lm.materials.tet_material.size(), 2u);
  EXPECT_EQ(lm.materials.of_tet(0).youngs_modulus_pa, 3000.0);
  EXPECT_EQ(lm.materials.of_tet(0).poisson_ratio, 0.45);
  EXPECT_EQ(lm.materials.of_tet(1).youngs_modulus_pa, 1500.0);
  EXPECT_EQ(lm.materials.of_tet(1).poisson_ratio, 0.4);

  // The global K from the compiled map equals the element matrices of each tetrahedron with
  // the material its label names, added by hand.
  const fem::SparseMatrix k = fem::assemble_stiffness(lm.mesh, lm.materials);
  Eigen::MatrixXd hand = Eigen::MatrixXd::Zero(15, 15);
  const fem::Material mat[2] = {{3000.0, 0.45, "mesh"}, {1500.0, 0.4, "soft"}};
  for (int t = 0; t < 2; ++t) {
    const auto& tet = lm.mesh.tets()[t];
    const int label = lm.mesh.tet_labels()[t];
    fem::TetNodes x;
    for (int a = 0; a < 4; ++a) x[a] = lm.mesh.vertices()[tet[a]];
    const fem::ElementMatrix ke = fem::tet_stiffness(x, mat[label - 1], t);
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b)
        hand.block<3, 3>(3 * tet[a], 3 * tet[b]) += ke.block<3, 3>(3 * a, 3 * b);
  }
  const Eigen::MatrixXd dense = Eigen::MatrixXd(k);
  EXPECT_LT((dense - hand).norm(), 1e-12 * hand.norm());
  // And differs from the uniform material's K: the tissue's material is used, not ignored.
  const Eigen::MatrixXd uniform =
      Eigen::MatrixXd(fem::assemble_stiffness(lm.mesh, fem::MaterialMap::uniform(mat[0])));
  EXPECT_GT((dense - uniform).norm(), 1e-3 * uniform.norm());
}

TEST_F(RigidTissue, TetrahedronWithUnlistedLabelRefused) {
  const std::string e = refusal(brain_entry("tissues { label: 1 name: \"cerebrum\" }"));
  EXPECT_NE(e.find("tetrahedron 1 has label 2, which no tissue lists"), std::string::npos) << e;
  EXPECT_NE(e.find("t.scene"), std::string::npos) << e;
}

TEST(TriSurface, MeditSurfaceReaderNeedsTriangles) {
  const auto dir = testing::temp_dir("tri_surface");
  {
    std::ofstream out(dir / "none.mesh");
    out << "MeshVersionFormatted 1\nDimension 3\nVertices\n1\n0 0 0 0\nEnd\n";
  }
  const std::string e = message_of([&] { mesh::read_medit_surface((dir / "none.mesh").string()); });
  EXPECT_NE(e.find("no Triangles section"), std::string::npos) << e;
  write_tet_surface(dir / "closed.mesh");
  const mesh::MeshData d = mesh::read_medit_surface((dir / "closed.mesh").string(), 0.001);
  EXPECT_EQ(d.triangles.size(), 4u);
  EXPECT_TRUE(d.tets.empty());
  EXPECT_NEAR(d.vertices_m[3].z(), 0.01, 1e-15);
  // The volume reader still wants tetrahedra.
  EXPECT_THROW(mesh::read_medit((dir / "closed.mesh").string()), std::runtime_error);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace neurosim::scene
