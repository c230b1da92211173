// Scene files (idl/scene.proto, protobuf text format): reading and validation, and the settings
// part of a scene (everything but the meshes) as plain C++. compile.hpp builds the whole Model.
#pragma once

#include "scene.pb.h"
#include "server/model/settings.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <filesystem>
#include <string>

namespace neurosim::scene {

// Largest scene file read, unit bytes (scenes are a few kB of text; a FIFO or device that never
// ends is refused at this size).
inline constexpr std::size_t kMaxSceneFileBytes = std::size_t{16} << 20;

// Reads and validates a scene file. Throws std::runtime_error naming the file, and line and
// column for syntax errors ("scenes/x.scene:12:7: ...") or the field for invalid values
// ("scenes/x.scene: meshes[1].material.poisson_ratio: 0.5 is outside (-1, 0.5)").
Scene read_scene(const std::filesystem::path& path);
// The same for text already in memory; `source` names it in messages.
Scene parse_scene(const std::string& text, const std::string& source);
// Semantic checks on a parsed scene (ids unique and referenced ones present, materials,
// regions, tools, rates, components) and plausible ranges (SI units; the table is ranges.hpp:
// E in [1e-3, 1e12] Pa, rates.step_hz in [10, 1e5] Hz, rates.status_hz in [0.1, 100] Hz, a
// prescribed displacement within 1 m, ...). Throws std::runtime_error naming the field and the
// allowed range.
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
