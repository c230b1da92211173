// A validated scene compiled into a Model (model.hpp): meshes read or generated, fixed regions,
// loads and prescribed displacements resolved to node sets, couplings resolved and checked.
// Every scene check that needs the meshes lives here; the rest is in scene.cpp.
#pragma once

#include "server/model/model.hpp"
#include "server/scene/generated_meshes.hpp"
#include "server/scene/scene.hpp"

#include <filesystem>
#include <string>
#include <vector>

namespace neurosim::scene {

// Throws std::runtime_error naming the scene file, the field and the element on bad input
// ("x.scene: couplings[0] (brain / artery): the host must have the lower priority").
// generated_meshes: where generated meshes are kept and taken from (none: each is generated).
Model compile(const Scene& scene, const std::string& source,
              GeneratedMeshes* generated_meshes = nullptr);
// read_scene + compile.
Model load_model(const std::filesystem::path& path);

// Builds one mesh entry: reads the file (relative paths are relative to scene_dir) or runs
// the generator (or takes its mesh from generated_meshes, if given), then resolves the fixed
// regions. `source` is the scene file for messages.
LoadedMesh load_mesh(const Mesh& entry, const std::filesystem::path& scene_dir,
                     const std::string& source, GeneratedMeshes* generated_meshes = nullptr);

// A rigid mesh entry: the Medit surface read (relative to scene_dir), checked closed and
// outward (errors name the file and the mesh), openings resolved (axis normalised).
RigidSurface load_rigid(const Mesh& entry, const std::filesystem::path& scene_dir,
                        const std::string& source);

// The entry's tissues resolved on a built mesh: out.tissues, and out.materials per tetrahedron
// (uniform(out.material) unless a tissue has its own material). A tetrahedron whose label no
// tissue lists is an error naming it. `what` names the mesh in messages.
void resolve_tissues(const Mesh& entry, const std::string& what, LoadedMesh& out);

// Nodes of `mesh` selected by `region` (sorted, unique). `what` names the region in messages;
// a region that selects nothing is an error (a typo in a box should not pass silently).
std::vector<int> select_nodes(const mesh::TetMesh& mesh, const Region& region,
                              const std::string& what);

// Scene material to the FEM material (validated; errors name `what`).
fem::Material to_material(const Material& material, const std::string& what);
// The scene's Prony series as fem::Viscoelastic (not validated here: to_material does it).
fem::Viscoelastic to_viscoelastic(const Viscoelastic& v);

}  // namespace neurosim::scene
