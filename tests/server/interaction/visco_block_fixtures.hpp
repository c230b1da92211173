// The viscoelastic block the relaxation tests press (tier_viscoelastic_test,
// viscoelastic_history_test): a 20 mm cube (E 3 kPa unless set, nu 0.45) fixed at its base, its
// material's Prony terms, one spherical probe; the tip pressed into the top face near its centre.
#pragma once

#include "server/interaction/simulation.hpp"
#include "server/scene/compile.hpp"

#include <memory>
#include <sstream>
#include <string>
#include <vector>

namespace neurosim::interaction::visco_testing {

constexpr double kTip = 0.003;  // tip radius, unit m
constexpr double kTop = 0.02;   // the block's top face, unit m

struct BlockSpec {
  std::vector<fem::PronyTerm> terms;  // none: an elastic block
  double youngs_modulus_pa{3000.0};
  std::string tier{"LINEAR"};  // effects.tier
  std::string element{};       // the material's element (empty: the scene default)
};

inline std::string block_scene(const BlockSpec& b) {
  std::ostringstream o;
  o.precision(17);
  o << "name: \"visco_block\"\n"
    << "meshes { id: \"block\" generate { box { min_m { x: 0 y: 0 z: 0 } max_m { x: 0.02 y: 0.02 "
       "z: 0.02 } } cell_size_m: 0.004 seed: 1 }\n"
    << "  material { name: \"tissue\" youngs_modulus_pa: " << b.youngs_modulus_pa
    << " poisson_ratio: 0.45\n";
  if (!b.element.empty()) o << "    element: \"" << b.element << "\"\n";
  if (!b.terms.empty()) {
    o << "    viscoelastic { source: \"test values\"\n";
    for (const auto& t : b.terms)
      o << "      terms { g: " << t.g << " tau_s: " << t.tau_s << " }\n";
    o << "    }\n";
  }
  o << "  }\n"
    << "  fixed { box { min_m { x: -1 y: -1 z: -1 } max_m { x: 1 y: 1 z: 1e-6 } } } }\n"
    << "tools { id: \"probe\" tip_radius_m: " << kTip
    << " shaft_radius_m: 0.001 shaft_length_m: 0.05 max_speed_m_per_s: 2 }\n"
    << "effects { tier: " << b.tier
    << " coupling: false tool_contact: true deformation_output: true }\n";
  return o.str();
}

inline std::unique_ptr<Simulation> build_block(const BlockSpec& b, const SimulationOptions& o) {
  return Simulation::build(
      scene::compile(scene::parse_scene(block_scene(b), "visco_block.scene"), "visco_block.scene"),
      o);
}

// The tip `depth_m` into the top face near its centre (negative: above it).
inline std::vector<ToolPose> press(double depth_m) {
  ToolPose p;
  p.tip_m = Vec3(0.0101, 0.0098, kTop + kTip - depth_m);
  p.axis = Vec3::UnitZ();
  return {p};
}

}  // namespace neurosim::interaction::visco_testing
