// Generated meshes kept by their scene block (see generated_meshes.hpp).
#include "server/scene/generated_meshes.hpp"

namespace neurosim::scene {

mesh::GeneratedMesh GeneratedMeshes::get(const Generator& block,
                                         const std::function<mesh::GeneratedMesh()>& make) {
  // The serialized bytes are the block's every field, doubles bit for bit (-0.0 is not 0.0).
  const std::string key = block.SerializeAsString();
  std::lock_guard<std::mutex> lock(mutex_);
  if (const auto it = kept_.find(key); it != kept_.end()) {
    ++reused_;
    return it->second;
  }
  mesh::GeneratedMesh made = make();
  ++made_;
  if (!made.optimization_time_limited) kept_.emplace(key, made);
  return made;
}

int GeneratedMeshes::made() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return made_;
}

int GeneratedMeshes::reused() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return reused_;
}

}  // namespace neurosim::scene
