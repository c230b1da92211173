// Small cube/cylinder scenes (paper Figure 8c at test size) built from scene text.
#pragma once

#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/generated_meshes.hpp"

#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim::interaction::testing {

struct SceneSpec {
  bool coupling{true};
  double host_e_pa{1.0e6};
  double embedded_e_pa{1.0e5};
  double nu{0.4};
  double host_cell_m{0.012};
  double embedded_cell_m{0.01};
  double tip_radius_m{0.015};
  bool embedded_fixed{false};  // fix the cylinder's end (then it is a body of its own untied)
  bool iterative{false};       // coupling method ITERATIVE (the paper's baseline)
  bool sliding{false};         // coupling kind SLIDING (frictionless unilateral) instead of TIE
  // A second embedded mesh (a thin vertical rod, r = 5 mm, axis x = 0.02, y = 0.05 m, z from
  // 0.025 to 0.075 m), coupled by this kind
  // ("TIE" or "SLIDING"); empty: none.
  std::string rod_kind{};
  std::string tier{"LINEAR"};  // effects.tier
  std::string element{};       // every material's element (empty: the scene default)
};

inline std::string element_field(const SceneSpec& s) {
  return s.element.empty() ? std::string() : " element: \"" + s.element + "\"";
}

// Cube [0, 0.1]^3 m fixed at z = 0; cylinder r = 15 mm along y through (0.05, *, 0.05), 60 mm long.
inline std::string scene_text(const SceneSpec& s) {
  std::ostringstream o;
  o.precision(17);
  o << "name: \"test\"\n"
    << "meshes { id: \"cube\" generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.1 y: 0.1 z: "
       "0.1 } } "
    << "cell_size_m: " << s.host_cell_m << " seed: 1 }\n"
    << "  material { name: \"host\" youngs_modulus_pa: " << s.host_e_pa
    << " poisson_ratio: " << s.nu << element_field(s) << " }\n"
    << "  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-6 } } } priority: 0 }\n"
    << "meshes { id: \"cylinder\" generate { cylinder { base_center_m { x: 0.05 y: 0.02 z: 0.05 } "
    << "axis_m { x: 0 y: 0.06 z: 0 } radius_m: 0.015 } cell_size_m: " << s.embedded_cell_m
    << " seed: 1 }\n"
    << "  material { name: \"embedded\" youngs_modulus_pa: " << s.embedded_e_pa
    << " poisson_ratio: " << s.nu << element_field(s) << " }\n";
  if (s.embedded_fixed)
    o << "  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 0.0201 z: 1 } } }\n";
  o << "  priority: 1 }\n"
    << "couplings { host: \"cube\" embedded: \"cylinder\" kind: " << (s.sliding ? "SLIDING" : "TIE")
    << " method: " << (s.iterative ? "ITERATIVE" : "EXACT") << " }\n";
  if (!s.rod_kind.empty()) {
    o << "meshes { id: \"rod\" generate { cylinder { base_center_m { x: 0.02 y: 0.05 z: 0.025 } "
      << "axis_m { x: 0 y: 0 z: 0.05 } radius_m: 0.005 } cell_size_m: 0.004 seed: 1 }\n"
      << "  material { name: \"rod\" youngs_modulus_pa: " << s.embedded_e_pa
      << " poisson_ratio: " << s.nu << " } priority: 1 }\n"
      << "couplings { host: \"cube\" embedded: \"rod\" kind: " << s.rod_kind << " }\n";
  }
  o << "tools { id: \"probe\" tip_radius_m: " << s.tip_radius_m
    << " shaft_radius_m: 0.002 shaft_length_m: 0.12 max_speed_m_per_s: 2 }\n"
    << "effects { tier: " << s.tier << " coupling: " << (s.coupling ? "true" : "false")
    << " tool_contact: true deformation_output: true }\n";
  return o.str();
}

// The generated meshes are kept for the whole process: the scenes a test builds (coupled or not,
// TIE or SLIDING, other moduli) mesh each generate block once; a kept mesh is the one the
// generator makes again (scene_generated_meshes_test).
inline scene::Model make_scene(const SceneSpec& s) {
  static scene::GeneratedMeshes kept;
  return scene::compile(scene::parse_scene(scene_text(s), "test.scene"), "test.scene", &kept);
}

// Tool tip on the cube's right face (x = 0.1) at (y, z) = (0.05, 0.05), pushed `depth_m` in -x.
inline ToolPose push_right(double depth_m, double tip_radius_m = SceneSpec{}.tip_radius_m) {
  ToolPose p;
  p.tip_m = Vec3(0.1 + tip_radius_m - depth_m, 0.05, 0.05);
  p.axis = Vec3::UnitX();
  return p;
}

// A simulation built from a SceneSpec and stepped once with the given poses.
struct Stepped {
  std::unique_ptr<Simulation> sim;
  std::vector<ToolContact> contacts;
  StepStats stats;
};

inline Stepped run(const SceneSpec& spec, const std::vector<ToolPose>& poses,
                   const SimulationOptions& options = {}) {
  Stepped s;
  s.sim = Simulation::build(make_scene(spec), options);
  s.sim->step(poses, s.contacts, s.stats);
  return s;
}

}  // namespace neurosim::interaction::testing
