// Meshes made by the generator, kept by their scene block: a process that compiles the same
// `generate` block several times (a test building variants of one scene) meshes it once. The
// generator is deterministic (the same block, seed included, gives the same mesh bit for bit,
// mesh_generate_test), so a kept mesh is the one a new run would make; a mesh whose sliver steps
// stopped at their wall-clock limit depends on the machine's load and is not kept.
#pragma once

#include "server/mesh/generate.hpp"
#include "server/scene/scene.hpp"

#include <functional>
#include <map>
#include <mutex>
#include <string>

namespace neurosim::scene {

class GeneratedMeshes {
 public:
  // The mesh of `block`: made by `make` on the first request of this block, a copy of it after.
  mesh::GeneratedMesh get(const Generator& block,
                          const std::function<mesh::GeneratedMesh()>& make);
  int made() const;    // meshes made by `make`
  int reused() const;  // requests answered from a kept mesh

 private:
  mutable std::mutex mutex_;
  std::map<std::string, mesh::GeneratedMesh> kept_;  // by the block's serialized bytes
  int made_{0}, reused_{0};
};

}  // namespace neurosim::scene
