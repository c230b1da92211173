// A scene compiled into plain C++ (MuJoCo's mjModel: built once, constant afterwards): meshes
// built with their materials and fixed nodes, couplings resolved to mesh indices and checked
// (roles by priority, one host per embedded mesh, no nesting), tools, effects, rates, haptics,
// loads and prescribed displacements resolved to node sets. No protobuf or DDS type: the physics
// (server/interaction) and the static solver read this, never the scene file.
// Made by server/scene/compile.hpp (the scene checks live there and in scene.cpp).
#pragma once

#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "server/model/rigid.hpp"
#include "server/model/settings.hpp"

#include <array>
#include <string>
#include <vector>

namespace neurosim::scene {

// A named label of a mesh (scene Tissue): the tetrahedra with this label, their material.
struct TissueDef {
  int label{0};
  std::string name;
  bool own_material{false};  // false: the mesh's material
  fem::Material material;    // the tissue's material (the mesh's when own_material is false)
  std::string material_source;
  std::string provenance;
};

// A scene mesh, built: geometry, material and fixed nodes resolved.
struct LoadedMesh {
  std::string id;
  mesh::TetMesh mesh;
  fem::Material material;  // the mesh's material (every tetrahedron's unless tissues say else)
  // Per tetrahedron: uniform(material), or per_tet when a tissue carries its own material.
  fem::MaterialMap materials;
  std::vector<TissueDef> tissues;  // scene order; empty when the scene names none
  std::vector<int> fixed_nodes;  // sorted, unique
  int priority{0};               // higher wins in an overlap (paper 2.4: vessel over brain)
  std::string provenance;
  std::string material_source;        // where E and nu come from
  double generator_cell_size_m{0.0};  // for generated meshes: the mesher's cell size, unit m

  // The first tissue whose own material differs from the mesh's in E or nu (other physics), or
  // nullptr when every tetrahedron has the mesh's E and nu: then a solver that runs one material
  // per mesh (the interactive server, coupled static solves) runs this mesh exactly.
  const TissueDef* tissue_with_other_material() const {
    for (const auto& t : tissues)
      if (t.own_material && (t.material.youngs_modulus_pa != material.youngs_modulus_pa ||
                             t.material.poisson_ratio != material.poisson_ratio))
        return &t;
    return nullptr;
  }
};

enum class CouplingKind { kTie, kSliding };
enum class CouplingMethod { kExact, kIterative };

// Two overlapping meshes: the embedded one (higher priority) keeps its volume, the host gets the
// new boundary S' around it.
struct CouplingDef {
  int host{-1};      // mesh index
  int embedded{-1};  // mesh index
  CouplingKind kind{CouplingKind::kTie};
  CouplingMethod method{CouplingMethod::kExact};  // kIterative: the paper's baseline (ties only)
};

// Nodal forces for static solves (distribution resolved: the force on every listed node).
struct LoadDef {
  int mesh{-1};
  std::vector<int> nodes;  // sorted, unique
  mesh::Vec3 force_per_node_n{mesh::Vec3::Zero()};  // unit N
};

// Prescribed displacement of some components of a node set (static solves; CalculiX's
// *BOUNDARY NSET,first,last): the components not held stay free.
struct PrescribedDef {
  int mesh{-1};
  std::vector<int> nodes;  // sorted, unique
  mesh::Vec3 displacement_m{mesh::Vec3::Zero()};  // unit m (only held components are used)
  std::array<bool, 3> components{{true, true, true}};  // x, y, z held
};

struct Model : Settings {
  std::vector<LoadedMesh> meshes;        // scene order
  std::vector<CouplingDef> couplings;    // scene order (applied when effects.coupling)
  std::vector<LoadDef> loads;            // scene order
  std::vector<PrescribedDef> prescribed;  // scene order
  // Rigid obstacles (scene meshes with `rigid`), scene order; not in `meshes` (no FEM), empty
  // and free for a scene without them. Constant data for tool contact; compile() does none.
  std::vector<RigidSurface> rigid;
  // Input that compiles but is most likely a mistake (compile.cpp: a mesh far larger or smaller
  // than a surgical scene, i.e. read in the wrong unit), one line each naming the scene file,
  // the mesh and the fix. compile() never prints: the programs print them to stderr.
  std::vector<std::string> warnings;

  // Index of the mesh with this id, or -1.
  int find_mesh(const std::string& id) const {
    for (std::size_t i = 0; i < meshes.size(); ++i)
      if (meshes[i].id == id) return static_cast<int>(i);
    return -1;
  }

  // Every mesh (its material, tissue materials and material map) on `element`: the programs'
  // --element option, applied before anything is built from the Model.
  void set_element(fem::Element element) {
    for (auto& m : meshes) {
      m.material.element = element;
      for (auto& mat : m.materials.materials) mat.element = element;
      for (auto& t : m.tissues) t.material.element = element;
    }
  }
};

}  // namespace neurosim::scene
