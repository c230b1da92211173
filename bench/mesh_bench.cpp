// Mesh component timings on a brain-sized mesh (16^3 cells x 6 = 24576 tetrahedra, 4913 vertices).
#include "server/mesh/io.hpp"
#include "server/mesh/quality.hpp"
#include "server/mesh/vtu.hpp"
#include "tests/server/mesh/mesh_fixtures.hpp"

#include <benchmark/benchmark.h>

#include <cstdio>
#include <filesystem>

namespace {

using namespace neurosim::mesh;

const testing::Arrays& grid() {
  static const testing::Arrays a = testing::grid_cube(16, 0.005);
  return a;
}

std::string temp(const char* name) {
  return (std::filesystem::temp_directory_path() / name).string();
}

void BM_Build(benchmark::State& state) {
  for (auto _ : state) {
    TetMesh m = TetMesh::build(grid().vertices, grid().tets);
    benchmark::DoNotOptimize(m.surface().data());
  }
  state.counters["tets"] = static_cast<double>(grid().tets.size());
}
BENCHMARK(BM_Build)->Unit(benchmark::kMillisecond);

void BM_Quality(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(quality(grid().vertices, grid().tets));
}
BENCHMARK(BM_Quality)->Unit(benchmark::kMillisecond);

void BM_ReadMedit(benchmark::State& state) {
  const std::string path = temp("neurosim_mesh_bench.mesh");
  MeshData d;
  d.vertices_m = grid().vertices;
  d.tets = grid().tets;
  write_medit(path, d);
  for (auto _ : state) benchmark::DoNotOptimize(read_medit(path).tets.data());
  std::remove(path.c_str());
}
BENCHMARK(BM_ReadMedit)->Unit(benchmark::kMillisecond);

void BM_WriteVtu(benchmark::State& state) {
  const std::string path = temp("neurosim_mesh_bench.vtu");
  const TetMesh m = TetMesh::build(grid().vertices, grid().tets);
  std::vector<Vec3> u(m.num_vertices(), Vec3(1e-3, -2e-4, 3.3e-5));
  for (auto _ : state) write_vtu(path, m, {make_field("displacement_m", u)});
  std::remove(path.c_str());
}
BENCHMARK(BM_WriteVtu)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
