// The skull of scenes/brain_skull.scene as a RigidObstacle, loaded once per test binary, and
// where its outer surface lies along a line (for driving a tool into it).
#pragma once

#include "server/interaction/rigid_obstacle.hpp"
#include "server/scene/compile.hpp"

#include <filesystem>
#include <memory>
#include <stdexcept>

namespace neurosim::interaction::testing {

inline const scene::Model& brain_skull_model() {
  static const scene::Model model =
      scene::load_model(std::filesystem::path(NEUROSIM_SOURCE_DIR) / "scenes/brain_skull.scene");
  return model;
}

inline const RigidObstacle& skull() {
  static const std::unique_ptr<const RigidObstacle> o =
      RigidObstacle::build(brain_skull_model().rigid);
  if (!o) throw std::runtime_error("brain_skull.scene has no rigid surface");
  return *o;
}

// First point inside the bone on the way from `from` (outside) along `dir` (unit), found in
// 0.05 mm steps by the winding number; throws if none within `max_m`.
inline mesh::Vec3 first_bone(const RigidObstacle& o, const mesh::Vec3& from, const mesh::Vec3& dir,
                             double max_m) {
  if (o.inside(from)) throw std::runtime_error("first_bone: start is inside the bone");
  for (double s = 0.0; s <= max_m; s += 5e-5)
    if (o.inside(from + s * dir)) return from + s * dir;
  throw std::runtime_error("first_bone: no bone on the line");
}

inline ToolShape probe_shape() {
  const auto& t = brain_skull_model().tools.front();
  return ToolShape{t.tip_radius_m, t.shaft_radius_m, t.shaft_length_m};
}

}  // namespace neurosim::interaction::testing
