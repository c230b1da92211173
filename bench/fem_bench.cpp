// fem_bench: cost of the linear FEM core on cube meshes.
//   fem_bench [--csv] [--quick]
// Per mesh: pattern build + assembly, CHOLMOD analysis + supernodal factorization, one
// compliance column, 300 columns one by one vs as block solves (blocks of 32, 64, 300), and
// the factor's size. Bottom face fixed; columns are the dofs of top-surface nodes.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/fem/assembly.hpp"
#include "server/fem/compliance.hpp"
#include "server/fem/static_solver.hpp"
#include "server/mesh/generate.hpp"
#include "tests/server/fem/fem_test_meshes.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

namespace {

using namespace neurosim;
using common::best_ms;

struct Case {
  std::string name;
  mesh::TetMesh mesh;
};

struct Row {
  std::string name;
  std::size_t nodes{0}, tets{0};
  int free_dofs{0};
  double pattern_ms{0}, assemble_ms{0}, analyze_ms{0}, factorize_ms{0}, column_ms{0};
  double singles300_ms{0}, block32_ms{0}, block64_ms{0}, block300_ms{0};
  int columns{0};
  long long factor_nnz{0};
  double factor_mb{0};
};

Row run(const Case& c) {
  Row r;
  r.name = c.name;
  r.nodes = c.mesh.num_vertices();
  r.tets = c.mesh.num_tets();
  const fem::MaterialMap brain =
      fem::MaterialMap::uniform({1.0e6, 0.4, "brain"});  // paper, Table 2
  Eigen::Vector3d lo, hi;
  c.mesh.bounds(lo, hi);
  const double tol = 1e-9 * (hi - lo).norm();
  std::vector<int> bottom, top;
  for (std::size_t v = 0; v < r.nodes; ++v) {
    if (c.mesh.vertices()[v].z() < lo.z() + tol) {
      bottom.push_back(static_cast<int>(v));
    }
  }
  for (int v : c.mesh.surface_vertices()) {
    if (c.mesh.vertices()[v].z() > lo.z() + tol) {
      top.push_back(v);
    }
  }
  // Prefer the top face, then other free surface nodes (small meshes have few top nodes).
  std::stable_sort(top.begin(), top.end(), [&](int a, int b) {
    return c.mesh.vertices()[a].z() > c.mesh.vertices()[b].z();
  });

  fem::SparseMatrix k;
  r.pattern_ms = best_ms(3, [&] { fem::StiffnessAssembler a(c.mesh); });
  const fem::StiffnessAssembler assembler(c.mesh);
  r.assemble_ms = best_ms(5, [&] { assembler.assemble(c.mesh, brain, k); });

  const fem::StaticSolver solver(c.mesh, brain, bottom);
  const auto& info = solver.factor_info();
  r.free_dofs = info.num_free_dofs;
  r.analyze_ms = 1e3 * info.analyze_s;
  r.factorize_ms = 1e3 * info.factorize_s;
  r.factor_nnz = info.factor_nnz;
  r.factor_mb = static_cast<double>(info.factor_bytes) / (1024.0 * 1024.0);

  std::vector<int> dofs;
  for (int v : top) {
    for (int a = 0; a < 3 && dofs.size() < 300; ++a) {
      dofs.push_back(3 * v + a);
    }
  }
  r.columns = static_cast<int>(dofs.size());
  r.column_ms = best_ms(5, [&] {
    fem::Compliance comp(solver);
    comp.column(dofs[0]);
  });
  r.singles300_ms = best_ms(2, [&] {
    fem::Compliance comp(solver);
    for (int d : dofs) {
      comp.column(d);
    }
  });
  auto block = [&](int size) {
    return best_ms(2, [&] {
      fem::ComplianceOptions o;
      o.block_columns = size;
      fem::Compliance comp(solver, o);
      comp.precompute(dofs);
    });
  };
  r.block32_ms = block(32);
  r.block64_ms = block(64);
  r.block300_ms = block(300);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  bool csv = false, quick = false;
  neurosim::cli::Parser cli("fem_bench", "Assembly, factorization and solve times of the FEM.");
  cli.add_flag("--csv", csv, "print CSV");
  cli.add_flag("--quick", quick, "small cases only");
  if (auto rc = cli.parse(argc, argv)) return *rc;
  std::vector<Case> cases;
  // Structured cubes (0.1 m, n^3 cells x 6 Kuhn tetrahedra), up to 16^3 x 6 = 24576 tetrahedra.
  for (int n : {4, 6, 8, 10, 12, 16}) {
    if (quick && n > 8) {
      break;
    }
    fem::testing::BoxSpec s{n, n, n, {0, 0, 0}, {0.1, 0.1, 0.1}};
    cases.push_back({"grid " + std::to_string(n) + "^3", fem::testing::box_mesh(s)});
  }
  // The paper's cube series (Table 3, 50..1812 vertices: a subset) and a brain-sized cube, CGAL
  // Mesh_3.
  for (int target : {50, 207, 535, 1013, 1812, 5300}) {
    if (quick && target > 535) {
      break;
    }
    mesh::MeshingOptions o;
    o.target_vertices = target;
    auto g = mesh::generate_box({0, 0, 0}, {0.1, 0.1, 0.1}, o);
    cases.push_back({"cgal " + std::to_string(target), std::move(g.mesh)});
  }
  if (csv) {
    std::printf(
        "mesh,nodes,tets,free_dofs,pattern_ms,assemble_ms,analyze_ms,factorize_ms,column_ms,"
        "columns,"
        "singles_ms,block32_ms,block64_ms,block300_ms,factor_nnz,factor_MB\n");
  } else {
    std::printf("%-11s %6s %6s %6s | %7s %8s %8s %9s | %7s %4s %9s %8s %8s %8s | %9s %7s\n", "mesh",
                "nodes", "tets", "dofs", "patt ms", "assem ms", "anal ms", "factor ms", "col ms",
                "cols", "single ms", "blk32", "blk64", "blk300", "nnz(L)", "L MB");
  }
  for (const Case& c : cases) {
    const Row r = run(c);
    if (csv) {
      std::printf("%s,%zu,%zu,%d,%.3f,%.3f,%.3f,%.3f,%.4f,%d,%.3f,%.3f,%.3f,%.3f,%lld,%.3f\n",
                  r.name.c_str(), r.nodes, r.tets, r.free_dofs, r.pattern_ms, r.assemble_ms,
                  r.analyze_ms, r.factorize_ms, r.column_ms, r.columns, r.singles300_ms,
                  r.block32_ms, r.block64_ms, r.block300_ms, r.factor_nnz, r.factor_mb);
    } else {
      std::printf(
          "%-11s %6zu %6zu %6d | %7.2f %8.2f %8.2f %9.2f | %7.3f %4d %9.2f %8.2f %8.2f %8.2f | "
          "%9lld %7.2f\n",
          r.name.c_str(), r.nodes, r.tets, r.free_dofs, r.pattern_ms, r.assemble_ms, r.analyze_ms,
          r.factorize_ms, r.column_ms, r.columns, r.singles300_ms, r.block32_ms, r.block64_ms,
          r.block300_ms, r.factor_nnz, r.factor_mb);
    }
    std::fflush(stdout);
  }
  return 0;
}
