// The simulation's set-up refuses a scene whose embedded mesh sticks out of its host while a
// tool touches tissue (its exposed part would have no contact rows); without tools it builds and
// ties only the embedded surface nodes inside the host and carves the host around them; the
// bundled scenes load.
#include "server/interaction/contact_surface.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {
namespace {

// The cube/cylinder scene with the cylinder's axis at height z_m (the cube's top at z = 0.1 m).
scene::Scene cube_cylinder(double z_m, bool tools) {
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  scene::Scene s = scene::read_scene(path);
  s.mutable_meshes(scene::find_mesh(s, "cylinder"))
      ->mutable_generate()
      ->mutable_cylinder()
      ->mutable_base_center_m()
      ->set_z(z_m);
  if (!tools) {
    s.clear_tools();
    s.mutable_effects()->set_tool_contact(false);
  }
  return s;
}

// The cube's contactable triangles as the simulation builds them (its contact slots, its fixed
// nodes, the faces the cylinder covers).
ContactSurface contact_surface(const Simulation& sim, int cube) {
  const CoupledBody& body = *sim.body_of(cube);
  std::vector<int> slot_of(body.host().num_vertices(), -1);
  for (std::size_t v = 0; v < slot_of.size(); ++v)
    slot_of[v] = body.contact_slot(static_cast<int>(v));
  return ContactSurface(ContactSurfaceDefinition{&body.host(), &slot_of, &sim.fixed_nodes(cube),
                                                 &body.covered_faces()});
}

bool on_cube_face(const mesh::Vec3& x) {
  for (int a = 0; a < 3; ++a)
    if (std::abs(x[a]) < 1e-9 || std::abs(x[a] - 0.1) < 1e-9) return true;
  return false;
}

std::array<int, 3> sorted(const std::array<int, 3>& t) {
  std::array<int, 3> f = t;
  std::sort(f.begin(), f.end());
  return f;
}

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

TEST(interaction_simulation_exposure, EnclosedCylinderLeavesOnlyTheCubesOuterFacesContactable) {
  // The bundled placement (axis at z = 0.05 m, inside): the carved cavity's faces are covered,
  // so every contact node lies on the cube's outer faces and every free node there is one.
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const scene::Scene s = cube_cylinder(0.05, true);
  const auto sim = Simulation::build(scene::compile(s, path.string()));
  const int cube = scene::find_mesh(s, "cube");
  const CoupledBody& body = *sim->body_of(cube);
  ASSERT_FALSE(body.covered_faces().empty());
  const auto& host = body.host();
  const auto& fixed = sim->fixed_nodes(cube);
  int outer = 0;
  for (int v : host.surface_vertices()) {
    const bool free = !std::binary_search(fixed.begin(), fixed.end(), v);
    if (on_cube_face(host.vertices()[v])) {
      outer += free;
      if (free) EXPECT_GE(body.contact_slot(v), 0) << "outer node " << v;
    } else {
      EXPECT_EQ(body.contact_slot(v), -1) << "cavity node " << v;
    }
  }
  EXPECT_EQ(static_cast<int>(body.contact_nodes().size()), outer);
  const ContactSurface surface = contact_surface(*sim, cube);
  for (const auto& t : surface.triangles())
    for (int v : t.node) EXPECT_TRUE(on_cube_face(host.vertices()[v])) << "node " << v;
}

TEST(interaction_simulation_exposure, RingAroundAnExitingCylinderStaysContactable) {
  // The cylinder 20 mm out of the cube's top (no tools: tool contact with it is refused). The
  // groove under it (S') is covered; every face of the cube's top around it is contactable,
  // also those with a node on S' (a rule by node would drop the ring around the exit).
  const auto path = neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
  const scene::Scene s = cube_cylinder(0.105, false);
  const auto sim = Simulation::build(scene::compile(s, path.string()));
  const int cube = scene::find_mesh(s, "cube");
  const CoupledBody& body = *sim->body_of(cube);
  const auto& host = body.host();
  const auto& covered = body.covered_faces();
  ASSERT_FALSE(covered.empty());
  const ContactSurface surface = contact_surface(*sim, cube);
  std::vector<std::array<int, 3>> contactable;
  for (const auto& t : surface.triangles()) {
    contactable.push_back(sorted(t.node));
    EXPECT_FALSE(std::binary_search(covered.begin(), covered.end(), contactable.back()));
  }
  std::sort(contactable.begin(), contactable.end());
  // No contactable face lies inside the cylinder (axis (0.05, y, 0.105) m for y in [0.02, 0.08]
  // m, radius 15 mm; 1 mm margin for its coarse polygon): the host is carved where B is, so no
  // host face coincides with B's.
  for (const auto& t : surface.triangles()) {
    mesh::Vec3 c = mesh::Vec3::Zero();
    for (int v : t.node) c += host.vertices()[v] / 3.0;
    const double r = std::hypot(c.x() - 0.05, c.z() - 0.105);
    EXPECT_FALSE(c.y() > 0.021 && c.y() < 0.079 && r < 0.015 - 0.001)
        << "contactable face inside the cylinder, centroid " << c.transpose();
  }
  const auto& boundary = body.boundary_nodes();
  int top = 0, ring = 0;
  for (const auto& tri : host.surface()) {
    bool in_top = true, on_boundary = false;
    for (int v : tri) {
      in_top = in_top && std::abs(host.vertices()[v].z() - 0.1) < 1e-9;
      on_boundary = on_boundary || std::binary_search(boundary.begin(), boundary.end(), v);
    }
    if (!in_top) continue;
    ++top;
    ring += on_boundary;
    EXPECT_TRUE(std::binary_search(contactable.begin(), contactable.end(),
                                   sorted({tri[0], tri[1], tri[2]})))
        << "top face " << tri[0] << " " << tri[1] << " " << tri[2];
  }
  EXPECT_GT(top, 0);
  EXPECT_GT(ring, 0);  // the ring around the exit touches S'
  std::printf("cube top: %d faces contactable, %d of them with a node on S'\n", top, ring);
  // Its nodes' normals point out of the top, not into the groove.
  for (std::size_t k = 0; k < body.contact_nodes().size(); ++k) {
    const mesh::Vec3& x = host.vertices()[body.contact_nodes()[k]];
    if (std::abs(x.z() - 0.1) < 1e-9 && x.x() > 1e-9 && x.x() < 0.1 - 1e-9 && x.y() > 1e-9 &&
        x.y() < 0.1 - 1e-9)
      EXPECT_GT(body.contact_normals()[k].z(), 1.0 - 1e-12) << "node " << body.contact_nodes()[k];
  }
}

}  // namespace
}  // namespace neurosim::interaction
