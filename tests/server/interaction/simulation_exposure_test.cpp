// The simulation's set-up refuses a scene whose embedded mesh sticks out of its host while a
// tool touches tissue (its exposed part would have no contact rows); without tools it builds and
// ties only the embedded surface nodes inside the host and carves the host around them; the
// bundled scenes load.
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {
namespace {

std::string build_error(const scene::Model& model) {
  try {
    (void)build_model(model, SimulationOptions{});
  } catch (const std::exception& ex) {
    return ex.what();
  }
  return {};
}

TEST(interaction_simulation_exposure, CylinderOutOfTheCubeIsRefused) {
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  scene::Scene s = scene::read_scene(path);
  // The cylinder (r = 15 mm, axis along y) moved up so that it sticks 20 mm out of the cube's
  // top face (z = 0.1 m): its axis at z = 0.105 m, its top at z = 0.12 m.
  auto* cyl =
      s.mutable_meshes(scene::find_mesh(s, "cylinder"))->mutable_generate()->mutable_cylinder();
  cyl->mutable_base_center_m()->set_z(0.105);
  const std::string what = build_error(scene::compile(s, path.string()));
  ASSERT_FALSE(what.empty()) << "an exposed embedded mesh was accepted with a tool";
  std::printf("refused as expected: %s\n", what.c_str());
  EXPECT_NE(what.find(path.string()), std::string::npos) << what;
  EXPECT_NE(what.find("embedded mesh cylinder"), std::string::npos) << what;
  EXPECT_NE(what.find("outside host cube"), std::string::npos) << what;
  EXPECT_NE(what.find("not implemented"), std::string::npos) << what;

  // Without tools nothing touches the exposed part: the same geometry builds, and only the
  // cylinder's surface nodes inside the cube (z <= 0.1 m + the tolerance) are tied.
  s.clear_tools();
  s.mutable_effects()->set_tool_contact(false);
  const scene::Model model = scene::compile(s, path.string());
  EXPECT_EQ(build_error(model), "");
  const auto sim = Simulation::build(model);
  const int cube = scene::find_mesh(s, "cube"), cylinder = scene::find_mesh(s, "cylinder");
  const auto& st = sim->setup_stats();
  EXPECT_GT(st.exposed_nodes, 0);
  EXPECT_GT(st.tied_nodes, 0);
  // The cube is carved around the part inside it (S' is open at the cube's top).
  EXPECT_GT(st.carved_tets, 0);
  const double tolerance_m = 0.1 * model.meshes[cube].mesh.mean_edge_length();
  const CoupledBody* body = sim->body_of(cylinder);
  ASSERT_NE(body, nullptr);
  ASSERT_EQ(body->ties().size(), 1u);
  const auto& tie = body->ties()[0];
  EXPECT_EQ(static_cast<int>(tie.tied_nodes().size()), st.tied_nodes);
  int above = 0;
  for (int v : tie.tied_nodes()) above += sim->mesh(cylinder).vertices()[v].z() > 0.1 + tolerance_m;
  EXPECT_EQ(above, 0) << "tied nodes outside the cube";
  int exposed = 0;
  for (int v : sim->mesh(cylinder).surface_vertices())
    exposed += sim->mesh(cylinder).vertices()[v].z() > 0.1 + tolerance_m;
  EXPECT_EQ(st.exposed_nodes, exposed);
}

TEST(interaction_simulation_exposure, BundledScenesLoad) {
  for (const char* name : {"cube_cylinder.scene", "brain_artery.scene", "brain_skull.scene",
                           "brain_viscoelastic.scene"}) {
    const auto path = neurosim::testing::source_dir() / "scenes" / name;
    const scene::Model model = scene::load_model(path);
    EXPECT_EQ(build_error(model), "") << name;
    const auto sim = Simulation::build(model);
    const auto& st = sim->setup_stats();
    std::printf("%s: carved tets %d, tied nodes %d, exposed nodes %d\n", name, st.carved_tets,
                st.tied_nodes, st.exposed_nodes);
    EXPECT_EQ(st.exposed_nodes, 0) << name;
  }
}

}  // namespace
}  // namespace neurosim::interaction
