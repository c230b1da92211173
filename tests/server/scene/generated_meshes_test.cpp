// Generated meshes kept by their scene block: a compile that takes a kept mesh gives the model a
// compile without the cache gives (the same vertices and tetrahedra, bit for bit); a block that
// differs in any field (here the seed, a coordinate's sign bit) is meshed anew; a mesh whose
// sliver steps hit their time limit is not kept.
#include "server/scene/generated_meshes.hpp"

#include "server/scene/compile.hpp"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

namespace neurosim::scene {
namespace {

// One generated box (4 cm, cells of 1 cm), the given seed and minimum x.
Scene box_scene(int seed, const std::string& min_x = "0") {
  return parse_scene(R"(
name: "box"
meshes {
  id: "block"
  generate { box { min_m { x: )" + min_x + R"( y: 0 z: 0 } max_m { x: 0.04 y: 0.04 z: 0.04 } }
             cell_size_m: 0.01 seed: )" + std::to_string(seed) + R"( }
  material { youngs_modulus_pa: 3000 poisson_ratio: 0.45 source: "test" }
  fixed { half_space { point_m { x: 1e-9 } normal { x: 1 } } }
}
)",
                     "box.scene");
}

void expect_same_mesh(const mesh::TetMesh& a, const mesh::TetMesh& b) {
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.tets().size(), b.tets().size());
  for (std::size_t v = 0; v < a.num_vertices(); ++v)  // bit for bit
    ASSERT_EQ(std::memcmp(a.vertices()[v].data(), b.vertices()[v].data(), 3 * sizeof(double)), 0)
        << "vertex " << v;
  for (std::size_t t = 0; t < a.tets().size(); ++t) ASSERT_EQ(a.tets()[t], b.tets()[t]) << "tet " << t;
}

TEST(GeneratedMeshes, KeptMeshIsTheOneACompileWithoutItMakes) {
  GeneratedMeshes kept;
  const Model fresh = compile(box_scene(1), "box.scene");
  const Model first = compile(box_scene(1), "box.scene", &kept);
  const Model second = compile(box_scene(1), "box.scene", &kept);
  EXPECT_EQ(kept.made(), 1);
  EXPECT_EQ(kept.reused(), 1);
  expect_same_mesh(first.meshes[0].mesh, fresh.meshes[0].mesh);
  expect_same_mesh(second.meshes[0].mesh, fresh.meshes[0].mesh);
  EXPECT_EQ(second.meshes[0].generator_cell_size_m, fresh.meshes[0].generator_cell_size_m);
  EXPECT_EQ(second.meshes[0].fixed_nodes, fresh.meshes[0].fixed_nodes);
  // Another seed, another block: meshed anew; so is -0 for 0 (another bit pattern).
  (void)compile(box_scene(2), "box.scene", &kept);
  EXPECT_EQ(kept.made(), 2);
  (void)compile(box_scene(1, "-0.0"), "box.scene", &kept);
  EXPECT_EQ(kept.made(), 3);
  EXPECT_EQ(kept.reused(), 1);
}

TEST(GeneratedMeshes, MeshStoppedByTheTimeLimitIsNotKept) {
  GeneratedMeshes kept;
  const Generator block = box_scene(1).meshes(0).generate();
  int runs = 0;
  const auto make = [&] {
    ++runs;
    mesh::GeneratedMesh m;
    m.optimization_time_limited = true;
    return m;
  };
  (void)kept.get(block, make);
  (void)kept.get(block, make);
  EXPECT_EQ(runs, 2);
  EXPECT_EQ(kept.made(), 2);
  EXPECT_EQ(kept.reused(), 0);
}

}  // namespace
}  // namespace neurosim::scene
