// ordering_bench: the host factor of the brain/artery scene per fill-reducing ordering
// (fem/factor_ordering.hpp), at several brain cell sizes (the scenes scale_bench uses:
// DIR/cC/brain_artery.scene, built by `neurosim-model --cell-size C` when missing).
// Per cell size and ordering: a StaticSolver of the scene's brain (its fixed nodes; not carved
// around the artery: the server removes a few hundred of its tetrahedra, the same for every
// ordering), and
// - nnz_l: nnz(L) (CHOLMOD's count), factor_mb: the supernodal factor's values and structure
//   (FactorInfo::factor_bytes), gflops: CHOLMOD's flop count of the factorization;
// - analyze_s (the ordering and symbolic analysis), factorize_s (numeric), peak_mb: the process's
//   peak resident memory while this solver was built (VmHWM reset before each);
// - solve_ms: one solve (a force on 3 surface nodes), block63_ms: one block solve of 63
//   right-hand sides (the column worker's block: 21 contact nodes' columns);
// - max_rel_diff: max |u - u_first| / max |u_first| against the first ordering's answer for the
//   same forces (round-off only: the ordering must not change the answer).
// - nnz_k: stored entries of the full stiffness K (the element's stencil: smoothed-tet couples
//   a node to its neighbours' neighbours; --element names another element for comparison).
//   ordering_bench --cell-size 5 --cell-size 3 [--ordering cholmod --ordering node-metis ...]
//                  [--element linear-tet] [--csv]
#include "patient_models.hpp"
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/fem/element.hpp"
#include "server/fem/static_solver.hpp"
#include "server/scene/compile.hpp"

#include <Eigen/Core>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace neurosim;

namespace {

using neurosim::bench::status_mb;

void reset_peak() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<double> cells;
  std::vector<std::string> orderings;
  std::string dir = "/tmp/neurosim_scale_bench";
  std::string element;
  bool csv = false;
  cli::Parser p("ordering_bench", "The brain's host factor per fill-reducing ordering.");
  p.add_option("--cell-size", cells, "brain cell size, unit mm (repeat)");
  p.add_option("--ordering", orderings,
               "cholmod, amd, metis, nesdis, node-metis (repeat; default: all; the first is the "
               "reference of max_rel_diff)");
  p.add_option("--models", dir, "folder of the built scenes")->capture_default_str();
  p.add_option("--element", element,
               "every mesh on this element instead of the scene's (the stencil sets the fill)");
  p.add_flag("--csv", csv, "CSV only");
  if (auto rc = p.parse(argc, argv)) return *rc;
  if (cells.empty()) cells = {7.0};
  if (orderings.empty()) orderings = {"cholmod", "amd", "metis", "nesdis", "node-metis"};
  std::printf("cell_mm,element,ordering,chosen,free_dofs,nnz_k,nnz_l,factor_mb,gflops,analyze_s,factorize_s,"
              "peak_mb,solve_ms,block63_ms,max_rel_diff\n");
  try {
    for (double cell : cells) {
      scene::Model model = scene::load_model(neurosim::bench::scene_at(cell, dir, "ordering_bench"));
      if (!element.empty()) {
        const auto e = fem::parse_element(element);
        if (!e) throw std::runtime_error("unknown element '" + element + "'");
        model.set_element(*e);
      }
      int host = model.find_mesh("brain");
      if (host < 0) host = 0;
      const auto& lm = model.meshes[static_cast<std::size_t>(host)];
      const int n = static_cast<int>(lm.mesh.num_vertices());
      // Forces: 1 N inwards on three surface nodes far apart; block: 63 unit columns.
      Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * n);
      const auto& surf = lm.mesh.surface_vertices();
      for (int k = 0; k < 3; ++k) f[3 * surf[(k * surf.size()) / 3] + k] = 1.0;
      Eigen::VectorXd reference;
      for (const std::string& name : orderings) {
        fem::SolverOptions o;
        o.ordering = fem::ordering_from_name(name);
        reset_peak();
        const auto t0 = common::Clock::now();
        fem::StaticSolver solver(lm.mesh, lm.materials, lm.fixed_nodes, o);
        const double build_s = common::seconds_since(t0);
        const double peak = status_mb("VmHWM");
        const fem::FactorInfo& info = solver.factor_info();
        Eigen::VectorXd u;
        solver.solve(f, u);  // warm
        auto ts = common::Clock::now();
        const int reps = 3;
        for (int r = 0; r < reps; ++r) solver.solve(f, u);
        const double solve_ms = 1e3 * common::seconds_since(ts) / reps;
        const int nf = solver.num_free_dofs();
        Eigen::MatrixXd b = Eigen::MatrixXd::Zero(nf, 63), x;
        for (int c = 0; c < 63; ++c) b((static_cast<long>(c) * nf) / 63, c) = 1.0;
        ts = common::Clock::now();
        solver.solve_reduced(b, x);
        const double block_ms = 1e3 * common::seconds_since(ts);
        double diff = 0.0;
        if (reference.size() == 0) reference = u;
        else diff = (u - reference).cwiseAbs().maxCoeff() / reference.cwiseAbs().maxCoeff();
        std::printf("%g,%s,%s,%s,%d,%lld,%lld,%.0f,%.1f,%.2f,%.2f,%.0f,%.1f,%.1f,%.2e\n", cell,
                    fem::element_name(lm.material.element), name.c_str(), info.ordering.c_str(), nf,
                    info.stiffness_nnz, info.factor_nnz, info.factor_bytes / 1e6,
                    info.factor_flops / 1e9, info.analyze_s, info.factorize_s, peak, solve_ms,
                    block_ms, diff);
        std::fflush(stdout);
        if (!csv)
          std::cerr << "ordering_bench: cell " << cell << " mm, " << name << ": solver built in "
                    << build_s << " s (assembly " << info.assembly_s << " s), "
                    << lm.mesh.num_vertices() << " vertices, " << lm.mesh.num_tets()
                    << " tetrahedra\n";
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "ordering_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
