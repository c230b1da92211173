// Scene files (idl/scene.proto, protobuf text format): reading, validation, and turning
// each mesh entry into a built TetMesh with its material and fixed nodes.
#pragma once

#include "scene.pb.h"
#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace neurosim::scene {

// Reads and validates a scene file. Throws std::runtime_error naming the file, and line and
// column for syntax errors ("scenes/x.scene:12:7: ...") or the field for invalid values
// ("scenes/x.scene: meshes[1].material.poisson_ratio: 0.5 is outside (-1, 0.5)").
Scene read_scene(const std::filesystem::path& path);
// The same for text already in memory; `source` names it in messages.
Scene parse_scene(const std::string& text, const std::string& source);
// Semantic checks on a parsed scene (ids unique and referenced ones present, materials,
// regions, tools, rates finite and positive). Throws std::runtime_error naming the field.
void validate_scene(const Scene& scene, const std::string& source);

// A scene mesh, built: geometry, material and fixed nodes resolved.
struct LoadedMesh {
  std::string id;
  mesh::TetMesh mesh;
  fem::Material material;
  std::vector<int> fixed_nodes;  // sorted, unique
  int priority{0};
  std::string provenance;
  double generator_cell_size_m{0.0};  // for generated meshes: the mesher's cell size, unit m
};

// Builds one mesh entry: reads the file (relative paths are relative to scene_dir) or runs
// the generator, then resolves the fixed regions. `source` is the scene file for messages.
LoadedMesh load_mesh(const Mesh& entry, const std::filesystem::path& scene_dir,
                     const std::string& source);

// Nodes of `mesh` selected by `region` (sorted, unique). `what` names the region in messages;
// a region that selects nothing is an error (a typo in a box should not pass silently).
std::vector<int> select_nodes(const mesh::TetMesh& mesh, const Region& region,
                              const std::string& what);

// Proto vector to Eigen (no unit change).
inline mesh::Vec3 to_vec3(const Vec3& v) { return {v.x(), v.y(), v.z()}; }
// Scene material to the FEM material (validated; errors name `what`).
fem::Material to_material(const Material& material, const std::string& what);

// Index of the mesh with this id, or -1.
int find_mesh(const Scene& scene, const std::string& id);

}  // namespace neurosim::scene
