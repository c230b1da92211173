// Scene files: parsing errors name file, line and field; regions; generated meshes.
#include "server/scene/compile.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <chrono>
#include <fstream>

namespace neurosim::scene {
namespace {

const char* kMinimal = R"(
name: "t"
meshes {
  id: "box"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.01 z: 0.01 } } target_vertices: 60 seed: 3 }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 }
  fixed { half_space { point_m { x: 1e-9 } normal { x: 1 } } }
}
)";

using testing::message_of;

TEST(Scene, BundledSceneParsesAndValidates) {
  const auto path = testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const Scene s = read_scene(path);
  EXPECT_EQ(s.name(), "cube_cylinder");
  ASSERT_EQ(s.meshes_size(), 2);
  EXPECT_EQ(s.couplings(0).host(), "cube");
  EXPECT_GT(s.meshes(1).priority(), s.meshes(0).priority());  // vessel-like over host
}

TEST(Scene, SyntaxErrorNamesFileLineAndColumn) {
  const std::string text = std::string(kMinimal) + "meshes { id: \"x\" bogus_field: 3 }\n";
  const std::string msg = message_of([&] { parse_scene(text, "bad.scene"); });
  EXPECT_NE(msg.find("bad.scene:9:29:"), std::string::npos) << msg;
  EXPECT_NE(msg.find("bogus_field"), std::string::npos) << msg;
}

TEST(Scene, InvalidMaterialNamesTheField) {
  std::string text = kMinimal;
  text.replace(text.find("0.45"), 4, "0.5");
  const std::string msg = message_of([&] { parse_scene(text, "m.scene"); });
  EXPECT_NE(msg.find("m.scene"), std::string::npos) << msg;
  EXPECT_NE(msg.find("meshes[0].material"), std::string::npos) << msg;
}

TEST(Scene, NonFiniteValuesAreRefused) {
  for (const char* bad : {"nan", "inf", "-inf"}) {
    std::string text = kMinimal;
    text.replace(text.find("3000"), 4, bad);
    EXPECT_THROW(parse_scene(text, "n.scene"), std::runtime_error) << bad;
    std::string t2 = kMinimal;
    t2.replace(t2.find("x: 0.02"), 7, std::string("x: ") + bad);
    const std::string msg = message_of([&] { parse_scene(t2, "n.scene"); });
    EXPECT_NE(msg.find("meshes[0].generate.box.max_m"), std::string::npos) << msg;
  }
}

TEST(Scene, DanglingReferencesAndDuplicatesAreRefused) {
  std::string text = std::string(kMinimal) + "couplings { host: \"box\" embedded: \"vessel\" }\n";
  std::string msg = message_of([&] { parse_scene(text, "c.scene"); });
  EXPECT_NE(msg.find("couplings[0].embedded"), std::string::npos) << msg;
  EXPECT_NE(msg.find("vessel"), std::string::npos) << msg;

  std::string dup = std::string(kMinimal) + std::string(kMinimal).substr(std::string(kMinimal).find("meshes"));
  msg = message_of([&] { parse_scene(dup, "d.scene"); });
  EXPECT_NE(msg.find("meshes[1].id"), std::string::npos) << msg;

  msg = message_of([&] { parse_scene("name: \"empty\"", "e.scene"); });
  EXPECT_NE(msg.find("e.scene: meshes"), std::string::npos) << msg;
}

TEST(Scene, MissingFileIsNamed) {
  const std::string msg = message_of([] { read_scene("/nonexistent/x.scene"); });
  EXPECT_NE(msg.find("/nonexistent/x.scene"), std::string::npos) << msg;
}

TEST(Scene, GeneratedMeshAndFixedRegion) {
  const Scene s = parse_scene(kMinimal, "min.scene");
  const LoadedMesh m = load_mesh(s.meshes(0), ".", "min.scene");
  EXPECT_GT(m.mesh.num_vertices(), 30u);
  EXPECT_EQ(m.mesh.inverted_fixed(), 0);
  ASSERT_FALSE(m.fixed_nodes.empty());
  for (int n : m.fixed_nodes) EXPECT_LE(m.mesh.vertices()[n].x(), 1e-9);
  // Every vertex on the x = 0 face is fixed, none elsewhere.
  std::size_t on_face = 0;
  for (const auto& x : m.mesh.vertices()) on_face += x.x() <= 1e-9;
  EXPECT_EQ(on_face, m.fixed_nodes.size());
  EXPECT_DOUBLE_EQ(m.material.youngs_modulus_pa, 3000.0);
}

TEST(Scene, RegionThatSelectsNothingIsAnError) {
  std::string text = kMinimal;
  text.replace(text.find("point_m { x: 1e-9 }"), 19, "point_m { x: -1 }");
  const Scene s = parse_scene(text, "r.scene");
  const std::string msg = message_of([&] { load_mesh(s.meshes(0), ".", "r.scene"); });
  EXPECT_NE(msg.find("fixed[0]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("selects no node"), std::string::npos) << msg;
}

TEST(Scene, MeshFileRelativeToSceneAndUnits) {
  const auto dir = testing::temp_dir("scene_file");
  {
    std::ofstream mesh(dir / "tet.mesh");
    mesh << "MeshVersionFormatted 1\nDimension 3\nVertices\n5\n0 0 0 1\n10 0 0 1\n0 10 0 1\n"
            "0 0 10 1\n50 50 50 1\nTetrahedra\n1\n1 2 3 4 7\nEnd\n";
  }
  const std::string text = R"(meshes { id: "t" file: "tet.mesh" file_unit_m: 0.001
    material { youngs_modulus_pa: 1e6 poisson_ratio: 0.3 }
    fixed { nodes { ids: 0 ids: 1 ids: 2 } } })";
  const Scene s = parse_scene(text, (dir / "t.scene").string());
  const LoadedMesh m = load_mesh(s.meshes(0), dir, (dir / "t.scene").string());
  EXPECT_EQ(m.mesh.num_vertices(), 4u);  // the unused vertex is dropped
  EXPECT_NEAR(m.mesh.vertices()[1].x(), 0.01, 1e-15);  // mm -> m
  EXPECT_EQ(m.mesh.tet_labels().at(0), 7);
  EXPECT_EQ(m.fixed_nodes, (std::vector<int>{0, 1, 2}));

  const std::string bad = R"(meshes { id: "t" file: "tet.mesh"
    material { youngs_modulus_pa: 1e6 poisson_ratio: 0.3 } fixed { nodes { ids: 99 } } })";
  const Scene s2 = parse_scene(bad, "b.scene");
  const std::string msg = message_of([&] { load_mesh(s2.meshes(0), dir, "b.scene"); });
  EXPECT_NE(msg.find("node id 99"), std::string::npos) << msg;
  std::filesystem::remove_all(dir);
}

// Values outside the plausible ranges are refused naming the field and the range (SI units):
// a 31-year sleep between steps, 2e9 steps per status period (two 16 GB arrays of step times),
// E = 1e300 Pa or a prescribed displacement of 1e30 m that would "solve successfully".
TEST(Scene, ImplausibleValuesAreRefusedNamingFieldAndRange) {
  const std::string load =
      R"(loads { mesh: "box" region { nodes { ids: 0 } } force_n { z: 1e30 } })";
  const std::string prescribed =
      R"(prescribed { mesh: "box" region { nodes { ids: 0 } } displacement_m { x: 1e30 } })";
  const std::string tool = R"(tools { id: "p" tip_radius_m: 10 })";
  const struct {
    std::string text;     // appended to kMinimal, or
    std::string replace;  // ... this in kMinimal replaced by `with`
    std::string with;
    std::string expected;  // in the message
  } cases[] = {
      {"rates { step_hz: 1e-9 }", "", "",
       "v.scene: rates.step_hz: 1e-09 is outside [10, 100000] Hz (0 or unset: the default)"},
      {"rates { status_hz: 1e-6 }", "", "",
       "v.scene: rates.status_hz: 1e-06 is outside [0.1, 100] Hz"},
      {"rates { viewer_hz: 1e9 }", "", "",
       "v.scene: rates.viewer_hz: 1e+09 is outside [0.1, 1000] Hz"},
      {"", "3000", "1e300",
       "v.scene: meshes[0].material.youngs_modulus_pa: 1e+300 is outside [0.001, 1e+12] Pa"},
      {prescribed, "", "", "v.scene: prescribed[0].displacement_m.x: 1e+30 is outside [-1, 1] m"},
      {load, "", "", "v.scene: loads[0].force_n.z: 1e+30 is outside [-1e+06, 1e+06] N"},
      {"", "target_vertices: 60", "target_vertices: 2000000000",
       "v.scene: meshes[0].generate.target_vertices: 2000000000 is outside [0, 300000]"},
      {"", "x: 0.02", "x: 1e6",
       "v.scene: meshes[0].generate.box.max_m.x: 1e+06 is outside [-10, 10] m"},
      {tool, "", "", "v.scene: tools[0].tip_radius_m: 10 is outside [0, 0.1] m"},
      {"haptics { force_scale: 1e9 }", "", "",
       "v.scene: haptics.force_scale: 1e+09 is outside [0.001, 1000]"},
      {"haptics { max_force_n: 1e5 }", "", "",
       "v.scene: haptics.max_force_n: 100000 is outside [0, 100] N"},
      {"max_stations: 100000", "", "", "v.scene: max_stations: 100000 is outside [0, 64]"},
  };
  for (const auto& c : cases) {
    std::string text = std::string(kMinimal) + c.text + "\n";
    if (!c.replace.empty()) text.replace(text.find(c.replace), c.replace.size(), c.with);
    const std::string msg = message_of([&] { parse_scene(text, "v.scene"); });
    EXPECT_NE(msg.find(c.expected), std::string::npos) << c.text << c.with << ": " << msg;
  }
  // The edges of the ranges are accepted.
  EXPECT_NO_THROW(
      parse_scene(std::string(kMinimal) + "rates { step_hz: 10 status_hz: 0.1 viewer_hz: 1000 }",
                  "edge.scene"));
}

// A scene path that is not a regular file (a device, a named pipe no one writes to) is refused
// before reading, naming it: the pipe would block the open for ever.
TEST(Scene, SpecialSceneFilesAreRefusedBeforeReading) {
  EXPECT_EQ(message_of([] { read_scene("/dev/zero"); }),
            "/dev/zero: scene file: is a character device, not a regular file");
  const auto fifo = (neurosim::testing::temp_dir("scene_fifo") / "pipe.scene").string();
  EXPECT_EQ(neurosim::testing::message_of_reading_a_fifo(
                fifo, [](const std::string& p) { read_scene(p); }),
            fifo + ": scene file: is a named pipe, not a regular file");
}

// A generated mesh whose expected size is absurd is refused before the mesher runs, naming the
// mesh and the scene field (this cell size would be about 2e13 tetrahedra: never finishes).
TEST(Scene, AbsurdGeneratedMeshIsRefusedBeforeMeshing) {
  std::string text = kMinimal;
  text.replace(text.find("target_vertices: 60"), 19, "cell_size_m: 1e-6");
  const Scene s = parse_scene(text, "g.scene");
  const auto t0 = std::chrono::steady_clock::now();
  const std::string msg = message_of([&] { load_mesh(s.meshes(0), ".", "g.scene"); });
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 5.0);
  EXPECT_NE(msg.find("g.scene: mesh \"box\": generate.cell_size_m: about 2e+13 tetrahedra "
                     "expected, above the limit of 2e+06"),
            std::string::npos)
      << msg;
}

}  // namespace
}  // namespace neurosim::scene
