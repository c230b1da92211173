// scenes/cube_cylinder.scene with the cylinder moved along z (the cube's top at z = 0.1 m: the
// bundled axis 0.05 m encloses it, 0.105 m raises its top 20 mm out of the cube), shared by the
// exposure tests and the tie's CalculiX comparison.
#pragma once

#include "server/scene/compile.hpp"
#include "server/scene/generated_meshes.hpp"
#include "server/scene/scene.hpp"
#include "test_support.hpp"

#include <filesystem>

namespace neurosim::interaction::testing {

inline std::filesystem::path cube_cylinder_path() {
  return neurosim::testing::source_dir() / "scenes" / "cube_cylinder.scene";
}

// The scene with the cylinder's axis at height z_m; without tools, tool contact is off too.
inline scene::Scene cube_cylinder_at(double z_m, bool tools) {
  scene::Scene s = scene::read_scene(cube_cylinder_path());
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

// scene::compile with the generated meshes kept for the whole process: the variants a test
// compiles (tier, coupling, materials, cylinder height) mesh each generate block once; a kept
// mesh is the one the generator makes again (scene_generated_meshes_test).
inline scene::Model compile_kept(const scene::Scene& s,
                                 const std::filesystem::path& path = cube_cylinder_path()) {
  static scene::GeneratedMeshes kept;
  return scene::compile(s, path.string(), &kept);
}

}  // namespace neurosim::interaction::testing
