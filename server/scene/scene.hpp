// Scene files (idl/scene.proto, protobuf text format): reading and validation, and the settings
// part of a scene (everything but the meshes) as plain C++. compile.hpp builds the whole Model.
#pragma once

#include "scene.pb.h"
#include "server/scene/settings.hpp"

#include <Eigen/Core>

#include <filesystem>
#include <string>

namespace neurosim::scene {

// Reads and validates a scene file. Throws std::runtime_error naming the file, and line and
// column for syntax errors ("scenes/x.scene:12:7: ...") or the field for invalid values
// ("scenes/x.scene: meshes[1].material.poisson_ratio: 0.5 is outside (-1, 0.5)").
Scene read_scene(const std::filesystem::path& path);
// The same for text already in memory; `source` names it in messages.
Scene parse_scene(const std::string& text, const std::string& source);
// Semantic checks on a parsed scene (ids unique and referenced ones present, materials,
// regions, tools, rates finite and positive, components). Throws std::runtime_error naming the
// field.
void validate_scene(const Scene& scene, const std::string& source);

// The settings of a validated scene with every default resolved (rates, haptics, tool speed,
// station limit; the image path made absolute against the scene file's folder).
Settings read_settings(const Scene& scene, const std::string& source);
// read_scene + read_settings: what a haptic station or a viewer reads of a scene.
Settings load_settings(const std::filesystem::path& path);

// Proto vector to Eigen (no unit change).
inline Eigen::Vector3d to_vec3(const Vec3& v) { return {v.x(), v.y(), v.z()}; }

// Index of the mesh with this id, or -1.
int find_mesh(const Scene& scene, const std::string& id);

}  // namespace neurosim::scene
