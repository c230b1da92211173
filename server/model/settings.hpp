// What a scene says besides its meshes: effects, elasticity tier, rates, haptics, tools, the
// volume image, the station limit. Plain C++ (no protobuf type), defaults resolved, validated by
// server/scene (scene.hpp read_settings); a haptic station reads only this part of a scene.
#pragma once

#include "server/fem/tier.hpp"

#include <array>
#include <string>
#include <vector>

namespace neurosim::scene {

// Elasticity tier a scene asks for (header-only enum shared with the physics).
using fem::Tier;
using fem::tier_name;

// Which effects the simulation builds and runs (nothing else is built).
struct EffectsDef {
  Tier tier{Tier::kLinear};
  bool coupling{false};            // inclusion decision + coupling of the scene's couplings
  bool tool_contact{false};        // unilateral contact of the tools against mesh surfaces
  bool deformation_output{false};  // displacement fields for viewers
  // The server warns once when the tier's expected tool-force error at the current strain
  // (fraction, from the measured table) exceeds this; 0: no bound.
  double max_expected_force_error{0.0};
};

struct RatesDef {
  double step_hz{1000.0};  // simulation step rate, unit Hz
  double viewer_hz{30.0};  // Deformation rate, unit Hz
  double status_hz{1.0};   // SimStatus rate, unit Hz
};

struct HapticsDef {
  double force_scale{1.0};      // device force = scale x simulated force (dimensionless)
  double workspace_scale{1.0};  // simulated displacement = scale x device displacement
  double max_force_n{3.3};      // clamp of the device force, unit N (Phantom Omni)
};

// A surgical tool: spherical tip on a cylindrical shaft.
struct ToolDef {
  std::string id;
  double tip_radius_m{0.0};       // > 0, unit m
  double shaft_radius_m{0.0};     // >= 0 (0: no shaft), unit m
  double shaft_length_m{0.0};     // >= 0, unit m
  double max_speed_m_per_s{2.0};  // faster ToolState jumps are rejected, unit m/s
};

// Volume image the meshes map to (viewers resample it through the deformed meshes).
struct ImageDef {
  std::string file;          // absolute path, or empty: none
  double file_unit_m{0.0};   // image physical coordinates x this = metres
};

// A craniotomy of a rigid mesh (scene meshes[].openings), for clients that place a workspace at
// it (neurosim-haptic --at-opening); the server's copy with the surface is scene::RigidOpening.
struct OpeningDef {
  std::string mesh;                      // the rigid mesh's id
  std::array<double, 3> center_m{};      // unit m
  std::array<double, 3> axis{0, 0, 1};   // unit, out of the head
  double radius_m{0.0};                  // unit m
};

struct Settings {
  std::string name;
  std::string description;
  std::string source;  // the scene file (or what stands for it), for messages
  EffectsDef effects;
  RatesDef rates;
  HapticsDef haptics;
  std::vector<ToolDef> tools;
  ImageDef image;
  std::vector<OpeningDef> openings;  // every rigid mesh's, in scene order
  int max_stations{8};
};

}  // namespace neurosim::scene
