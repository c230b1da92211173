// tier_bench: what each elasticity tier costs for the static equilibrium of a scene's host mesh.
//   tier_bench [--csv] [--scene S]... [--force N] [--element E]...
// Per scene, element (linear-tet, anp-tet, smoothed-tet) and served tier (LINEAR, NONLINEAR): set-up (assembly pattern + CHOLMOD symbolic analysis), one evaluation of
// the internal forces and of the tangent, the first equilibrium under a tool-like load (a force
// on the topmost surface node, in load increments) and one equilibrium update warm-started from
// it after the load grew 5 % (what a worker refreshing the equilibrium does), with its Newton
// iterations and the update rate it allows on one core. Best of 3 runs per timing.
// Side by side, the same updates with NewtonOptions::reuse_factorization (modified Newton with
// the last factor, refactorized only on poor contraction): a worker's steady state, 8 calls in
// a row each warm-started from the previous answer with the load alternating between 1.05 and
// 1.00 of the first (every call a 5 % change, the factor the one the previous call left); mean
// and worst time per call, mean iterations and factorizations per call, and the largest
// max |u_reuse - u_full| / max |u_full| against the full-Newton answer at 1.05.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/scene/compile.hpp"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

using namespace neurosim;
using common::best_ms;

int main(int argc, char** argv) {
  bool csv = false;
  std::vector<std::string> scenes{std::string(NEUROSIM_SOURCE_DIR) + "/scenes/cube_cylinder.scene",
                                  std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_artery.scene"};
  double force_n = 0.3;
  // smoothed-tet by request, with a smaller --force: under 0.3 N on the brain's topmost node its
  // NONLINEAR solve has no equilibrium to reach. From ~0.23 N the node sinks through the
  // tetrahedra under it (27 mm deep at 0.225 N, Green strain 34, tetrahedra inverted: the
  // smoothing cells average a single tetrahedron's inversion away, so none resists it alone);
  // the exact tangent is indefinite there and the projected one follows the node down. At
  // 0.1 N Newton converges quadratically (bench/RESULTS.md, "The locking-free elements").
  std::vector<std::string> elements{"linear-tet", "anp-tet"};
  cli::Parser cli("tier_bench", "Static-equilibrium cost of each elasticity tier (host meshes).");
  cli.add_flag("--csv", csv, "CSV output");
  cli.add_option("--scene", scenes, "scene file(s)");
  cli.add_option("--force", force_n, "tool-like force on the topmost surface node, N")
      ->check(cli::positive_number());
  cli.add_option("--element", elements, "elements to run")
      ->check(cli::one_of({"linear-tet", "anp-tet", "smoothed-tet"}))
      ->capture_default_str();
  if (auto rc = cli.parse(argc, argv)) return *rc;
  try {
    if (csv) {
      std::printf("scene,mesh,element,tier,nodes,tets,setup_ms,force_ms,tangent_ms,first_solve_ms,"
                  "first_iterations,update_ms,update_iterations,update_hz,max_u_mm,"
                  "reuse_update_ms,reuse_max_ms,reuse_iterations,reuse_factorizations,"
                  "reuse_update_hz,reuse_rel_diff\n");
    } else {
      std::printf("%-14s %-6s %-12s %-9s %6s %6s %9s %9s %10s %11s %5s %10s %5s %9s %8s | %9s %9s %5s "
                  "%5s %9s %9s\n",
                  "scene", "mesh", "element", "tier", "nodes", "tets", "setup ms", "force ms", "tangent ms",
                  "first ms", "its", "update ms", "its", "update Hz", "max u mm", "reuse ms",
                  "worst ms", "its", "facts", "reuse Hz", "rel diff");
    }
    for (const std::string& path : scenes) {
      const scene::Model model = scene::load_model(path);
      const scene::LoadedMesh& lm = model.meshes.front();  // the host
      const mesh::TetMesh& m = lm.mesh;
      int top = m.surface_vertices().front();
      for (int v : m.surface_vertices()) {
        if (m.vertices()[v].z() > m.vertices()[top].z()) top = v;
      }
      Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * m.num_vertices());
      f[3 * top + 2] = -force_n;
      for (const std::string& element_text : elements)
      for (fem::Tier tier : {fem::Tier::kLinear, fem::Tier::kNonlinear}) {
        std::unique_ptr<fem::EquilibriumSolver> solver;
        fem::Material material = lm.material;
        material.element = *fem::parse_element(element_text);
        const fem::MaterialMap mats = fem::MaterialMap::uniform(material);
        const double setup_ms = best_ms(3, [&] {
          solver = std::make_unique<fem::EquilibriumSolver>(
              fem::EquilibriumDefinition{&m, mats, tier, lm.fixed_nodes, {}, {}});
        });
        fem::EquilibriumResult first;
        int first_its = 0;
        const double first_ms = best_ms(3, [&] { first = solver->solve(f); });
        for (const auto& inc : first.increments) first_its += static_cast<int>(inc.residual_n.size()) - 1;
        Eigen::VectorXd fi;
        fem::SparseMatrix k;
        const double force_ms = best_ms(3, [&] { solver->forces().internal_force(first.displacement_m, fi); });
        const double tangent_ms =
            best_ms(3, [&] { solver->forces().tangent(first.displacement_m, false, k); });
        int update_its = 0;
        const Eigen::VectorXd f_more = 1.05 * f;
        Eigen::VectorXd u_full;
        const double update_ms = best_ms(3, [&] {
          u_full = first.displacement_m;
          const fem::NewtonIncrement inc = solver->solve_from(f_more, u_full);
          update_its = static_cast<int>(inc.residual_n.size()) - 1;
        });
        // Reused factorization: one untimed call back to the first load (the factor is then
        // whatever the reuse path leaves), then the timed steady state.
        fem::NewtonOptions reuse_options;
        reuse_options.reuse_factorization = true;
        Eigen::VectorXd u_reuse = u_full;
        solver->solve_from(f, u_reuse, reuse_options);
        constexpr int kReuseCalls = 8;
        double reuse_total_ms = 0.0, reuse_max_ms = 0.0, reuse_diff = 0.0;
        int reuse_its = 0, reuse_facts = 0;
        for (int call = 0; call < kReuseCalls; ++call) {
          const bool more = call % 2 == 0;
          fem::NewtonIncrement inc;
          const double ms = best_ms(1, [&] {
            inc = solver->solve_from(more ? f_more : f, u_reuse, reuse_options);
          });
          reuse_total_ms += ms;
          reuse_max_ms = std::max(reuse_max_ms, ms);
          reuse_its += static_cast<int>(inc.residual_n.size()) - 1;
          reuse_facts += inc.factorizations;
          if (more) {
            reuse_diff = std::max(reuse_diff, (u_reuse - u_full).cwiseAbs().maxCoeff() /
                                                  u_full.cwiseAbs().maxCoeff());
          }
        }
        const double reuse_ms = reuse_total_ms / kReuseCalls;
        const double max_u_mm = 1e3 * first.displacement_m.cwiseAbs().maxCoeff();
        const char* fmt =
            csv ? "%s,%s,%s,%s,%zu,%zu,%.2f,%.3f,%.3f,%.2f,%d,%.2f,%d,%.1f,%.3f,%.2f,%.2f,%.2f,%.2f,"
                  "%.1f,%.1e\n"
                : "%-14s %-6s %-12s %-9s %6zu %6zu %9.2f %9.3f %10.3f %11.2f %5d %10.2f %5d %9.1f "
                  "%8.3f | %9.2f %9.2f %5.2f %5.2f %9.1f %9.1e\n";
        std::printf(fmt, model.name.c_str(), lm.id.c_str(), element_text.c_str(), fem::tier_name(tier), m.num_vertices(),
                    m.num_tets(), setup_ms, force_ms, tangent_ms, first_ms, first_its, update_ms,
                    update_its, 1000.0 / update_ms, max_u_mm, reuse_ms, reuse_max_ms,
                    static_cast<double>(reuse_its) / kReuseCalls,
                    static_cast<double>(reuse_facts) / kReuseCalls, 1000.0 / reuse_ms,
                    reuse_diff);
        std::fflush(stdout);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tier_bench: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
