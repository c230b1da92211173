// Scene -> Model: every check that needs the meshes names the scene file and the field; settings
// come with their defaults; node sets and couplings are resolved to indices.
#include "server/scene/compile.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <functional>
#include <sstream>
#include <string>

namespace neurosim::scene {
namespace {

// Two boxes: "host" (priority 0, fixed at x = 0) and "inner" inside it (priority 1).
std::string two_boxes(const std::string& extra, int inner_priority = 1) {
  return R"(
name: "two"
meshes {
  id: "host"
  generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.04 y: 0.04 z: 0.04 } } cell_size_m: 0.01 seed: 1 }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 source: "test" }
  fixed { half_space { point_m { x: 1e-9 } normal { x: 1 } } }
  priority: 0
}
meshes {
  id: "inner"
  generate { box { min_m { x: 0.01 y: 0.01 z: 0.01 } max_m { x: 0.03 y: 0.03 z: 0.03 } } cell_size_m: 0.01 seed: 1 }
  material { youngs_modulus_pa: 30000 poisson_ratio: 0.4 }
  priority: )" + std::to_string(inner_priority) +
         "\n}\n" + extra;
}

using testing::message_of;

Model compile_text(const std::string& text, const std::string& source = "c.scene") {
  return compile(parse_scene(text, source), source);
}

TEST(SceneCompile, BundledSceneCompilesWithDefaultsResolved) {
  const auto path = testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const Model m = load_model(path);
  EXPECT_EQ(m.name, "cube_cylinder");
  EXPECT_EQ(m.source, path.string());
  ASSERT_EQ(m.meshes.size(), 2u);
  ASSERT_EQ(m.couplings.size(), 1u);
  EXPECT_EQ(m.couplings[0].host, m.find_mesh("cube"));
  EXPECT_EQ(m.couplings[0].embedded, m.find_mesh("cylinder"));
  EXPECT_EQ(m.effects.tier, Tier::kLinear);
  EXPECT_GT(m.rates.step_hz, 0.0);
  EXPECT_GT(m.haptics.max_force_n, 0.0);
  ASSERT_FALSE(m.tools.empty());
  EXPECT_GT(m.tools[0].max_speed_m_per_s, 0.0);
  EXPECT_FALSE(m.meshes[0].fixed_nodes.empty());
}

TEST(SceneCompile, SettingsDefaults) {
  const Model m = compile_text(two_boxes(""));
  const Settings defaults;
  EXPECT_EQ(m.rates.step_hz, defaults.rates.step_hz);
  EXPECT_EQ(m.rates.viewer_hz, defaults.rates.viewer_hz);
  EXPECT_EQ(m.rates.status_hz, defaults.rates.status_hz);
  EXPECT_EQ(m.haptics.max_force_n, defaults.haptics.max_force_n);
  EXPECT_EQ(m.max_stations, defaults.max_stations);
  EXPECT_EQ(m.meshes[0].material_source, "test");
  // A station reads the same settings without building meshes.
  const Settings s = read_settings(parse_scene(two_boxes("rates { step_hz: 500 }"), "c.scene"),
                                   "c.scene");
  EXPECT_EQ(s.rates.step_hz, 500.0);
  EXPECT_EQ(s.rates.viewer_hz, defaults.rates.viewer_hz);
}

TEST(SceneCompile, CouplingRolesAreCheckedByPriority) {
  const std::string tie = "couplings { host: \"host\" embedded: \"inner\" }\n"
                          "effects { coupling: true }\n";
  const Model ok = compile_text(two_boxes(tie));
  EXPECT_EQ(ok.couplings[0].kind, CouplingKind::kTie);
  EXPECT_EQ(ok.couplings[0].method, CouplingMethod::kExact);

  std::string msg = message_of([&] { compile_text(two_boxes(tie, 0)); });
  EXPECT_NE(msg.find("c.scene: couplings[0] (host / inner)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("equal priorities"), std::string::npos) << msg;
  msg = message_of([&] { compile_text(two_boxes(tie, -1)); });
  EXPECT_NE(msg.find("the host must have the lower priority"), std::string::npos) << msg;
}

TEST(SceneCompile, SlidingIterativeEmbeddedTwiceAndNestingAreRefused) {
  std::string msg = message_of([&] {
    compile_text(two_boxes("couplings { host: \"host\" embedded: \"inner\" kind: SLIDING "
                           "method: ITERATIVE }\neffects { coupling: true }\n"));
  });
  EXPECT_NE(msg.find("couplings[0]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("ITERATIVE"), std::string::npos) << msg;

  const std::string third = R"(
meshes {
  id: "core"
  generate { box { min_m { x: 0.015 y: 0.015 z: 0.015 } max_m { x: 0.025 y: 0.025 z: 0.025 } } cell_size_m: 0.01 seed: 1 }
  material { youngs_modulus_pa: 30000 poisson_ratio: 0.4 }
  priority: 2
}
effects { coupling: true }
)";
  msg = message_of([&] {
    compile_text(two_boxes(third + "couplings { host: \"host\" embedded: \"core\" }\n"
                                   "couplings { host: \"inner\" embedded: \"core\" }\n"));
  });
  EXPECT_NE(msg.find("couplings[1]"), std::string::npos) << msg;
  EXPECT_NE(msg.find("embedded twice"), std::string::npos) << msg;
  msg = message_of([&] {
    compile_text(two_boxes(third + "couplings { host: \"host\" embedded: \"inner\" }\n"
                                   "couplings { host: \"inner\" embedded: \"core\" }\n"));
  });
  EXPECT_NE(msg.find("inner is both host and embedded"), std::string::npos) << msg;
}

TEST(SceneCompile, ToolContactNeedsATool) {
  const std::string msg =
      message_of([&] { compile_text(two_boxes("effects { tool_contact: true }\n")); });
  EXPECT_NE(msg.find("c.scene: effects.tool_contact"), std::string::npos) << msg;
}

TEST(SceneCompile, LoadsAndPrescribedAreResolvedWithComponents) {
  const Model m = compile_text(two_boxes(R"(
loads { mesh: "host" region { half_space { point_m { x: 0.0399 } normal { x: -1 } } }
        force_n { z: -2 } distribution: TOTAL_SPLIT_EQUALLY }
prescribed { mesh: "host" region { box { min_m { x: 0.001 y: -1 z: 0.0399 } max_m { x: 1 y: 1 z: 1 } } }
             displacement_m { x: 0.5 z: -0.001 } components: "z" }
prescribed { mesh: "inner" region { nodes { ids: 0 } } displacement_m { y: 0.001 } }
)"));
  ASSERT_EQ(m.loads.size(), 1u);
  const auto& l = m.loads[0];
  ASSERT_FALSE(l.nodes.empty());
  EXPECT_NEAR(l.force_per_node_n.z() * static_cast<double>(l.nodes.size()), -2.0, 1e-12);
  ASSERT_EQ(m.prescribed.size(), 2u);
  EXPECT_EQ(m.prescribed[0].components, (std::array<bool, 3>{false, false, true}));
  EXPECT_EQ(m.prescribed[1].components, (std::array<bool, 3>{true, true, true}));
  EXPECT_EQ(m.prescribed[1].mesh, 1);
  for (int v : m.prescribed[0].nodes) EXPECT_GE(m.meshes[0].mesh.vertices()[v].z(), 0.0399);
}

TEST(SceneCompile, ContradictoryConstraintsNameTheNode) {
  // Fixed (x = 0 face) and prescribed.
  std::string msg = message_of([&] {
    compile_text(two_boxes("prescribed { mesh: \"host\" region { half_space { point_m { x: 1e-9 } "
                           "normal { x: 1 } } } displacement_m { z: 0.001 } }\n"));
  });
  EXPECT_NE(msg.find("c.scene: prescribed[0]: node"), std::string::npos) << msg;
  EXPECT_NE(msg.find("both fixed and prescribed"), std::string::npos) << msg;
  // The same node held twice with different z.
  msg = message_of([&] {
    compile_text(two_boxes(
        "prescribed { mesh: \"inner\" region { nodes { ids: 3 } } displacement_m { z: 0.001 } }\n"
        "prescribed { mesh: \"inner\" region { nodes { ids: 3 } } displacement_m { z: 0.002 } "
        "components: \"z\" }\n"));
  });
  EXPECT_NE(msg.find("prescribed[1]: node 3"), std::string::npos) << msg;
  // Held twice, other components: no contradiction.
  const Model ok = compile_text(two_boxes(
      "prescribed { mesh: \"inner\" region { nodes { ids: 3 } } displacement_m { z: 0.001 } "
      "components: \"z\" }\n"
      "prescribed { mesh: \"inner\" region { nodes { ids: 3 } } displacement_m { x: 0.002 } "
      "components: \"x\" }\n"));
  EXPECT_EQ(ok.prescribed.size(), 2u);
}

TEST(SceneCompile, BadComponentsNameTheField) {
  for (const char* bad : {"w", "zz", "x y"}) {
    const std::string msg = message_of([&] {
      compile_text(two_boxes(std::string("prescribed { mesh: \"inner\" region { nodes { ids: 3 } } "
                                         "displacement_m { z: 0.001 } components: \"") +
                             bad + "\" }\n"));
    });
    EXPECT_NE(msg.find("c.scene: prescribed[0].components"), std::string::npos) << bad << ": " << msg;
  }
}

// The size check: a mesh whose bounding-box diagonal is above 2 m or below 1 mm was most likely
// given in the wrong unit; compile() warns (scene file, mesh, size in m, the fix) and goes on.
// (A file in mm read as m: tests/server/interaction/stability_test.cpp.)
TEST(SceneCompile, SizeCheckWarnsAboutImplausibleMeshSizes) {
  EXPECT_TRUE(compile_text(two_boxes("")).warnings.empty());  // 40 mm: plausible
  auto one_box = [](double edge_m) {
    std::ostringstream s;
    s.precision(17);
    s << "name: \"size\"\nmeshes { id: \"block\" generate { box { min_m { x: 0 y: 0 z: 0 } "
      << "max_m { x: " << edge_m << " y: " << edge_m << " z: " << edge_m
      << " } } cell_size_m: " << edge_m / 2
      << " seed: 1 }\n  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 }\n"
      << "  fixed { half_space { point_m { z: " << edge_m / 100 << " } normal { z: 1 } } } }\n";
    return s.str();
  };
  const Model big = compile_text(one_box(1.2));  // diagonal 2.08 m
  ASSERT_EQ(big.warnings.size(), 1u);
  const std::string& w = big.warnings[0];
  EXPECT_NE(w.find("c.scene: mesh \"block\""), std::string::npos) << w;
  EXPECT_NE(w.find("diagonal 2.078 m"), std::string::npos) << w;
  EXPECT_NE(w.find("larger than 2 m"), std::string::npos) << w;
  EXPECT_NE(w.find("given in mm"), std::string::npos) << w;  // a generated mesh: no file unit
  EXPECT_TRUE(compile_text(one_box(1.1)).warnings.empty());  // diagonal 1.91 m
  const Model tiny = compile_text(one_box(5e-4));            // diagonal 0.87 mm
  ASSERT_EQ(tiny.warnings.size(), 1u);
  EXPECT_NE(tiny.warnings[0].find("smaller than 0.001 m"), std::string::npos) << tiny.warnings[0];
}

}  // namespace
}  // namespace neurosim::scene
