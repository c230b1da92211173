// neurosim-solve: static solve of a scene (loads and prescribed displacements) in an elasticity
// tier: linear (one factorization), corotational or nonlinear (Newton with load increments).
// Writes, per solved mesh, displacement.csv, reactions.csv and result.vtu; the first solved
// mesh (or --mesh ID) also at the top of --out, which is what verification scripts read.
#include "common/cli.hpp"
#include "common/clock.hpp"
#include "common/load_watch.hpp"
#include "server/fem/assembly.hpp"
#include "server/fem/cholmod_threads.hpp"
#include "server/fem/served_tiers.hpp"
#include "server/fem/equilibrium_solver.hpp"
#include "server/fem/static_solver.hpp"
#include "server/interaction/coupled_body.hpp"
#include "server/interaction/simulation.hpp"
#include "server/interaction/tier_equilibrium.hpp"
#include "server/mesh/quality.hpp"
#include "server/mesh/vtu.hpp"
#include "server/scene/compile.hpp"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <limits>
#include <map>
#include <sstream>
#include <string>

namespace fs = std::filesystem;
using neurosim::mesh::Vec3;

namespace {

const char* kDescription =
    "Static solve of every mesh the scene loads or constrains (SI units), in the scene's\n"
    "elasticity tier or --tier: linear, corotational, nonlinear (CalculiX's neo-Hookean).\n"
    "The corotational and nonlinear tiers use Newton with load increments (--increments N,\n"
    "default: chosen and cut back until Newton converges) and print the residual per increment.\n"
    "With effects.coupling, a host and the meshes TIE-coupled to it are solved as one body\n"
    "(exact tie, the host carved as the server carves it); --uncoupled solves every mesh on its\n"
    "own. SLIDING couplings are not applied (their meshes are solved on their own, with a\n"
    "note). Loads and prescribed displacements go on hosts or uncoupled meshes.";
const char* kFooter =
    "Writes DIR/<mesh>/{displacement.csv,reactions.csv,result.vtu} and copies the first solved\n"
    "mesh (or --mesh ID) to DIR/displacement.csv, DIR/reactions.csv, DIR/result.vtu. CSV\n"
    "headers: node,x,y,z,ux,uy,uz and node,x,y,z,rx,ry,rz (reactions: force the supports exert\n"
    "on the body).";

using neurosim::common::seconds_since;

struct MeshResult {
  Eigen::VectorXd u_m;
  Eigen::VectorXd reaction_n;
  std::vector<char> constrained;  // per node
};

void write_outputs(const fs::path& dir, const neurosim::mesh::TetMesh& mesh,
                   const std::vector<int>& fixed_nodes, const MeshResult& r) {
  fs::create_directories(dir);
  const auto& x = mesh.vertices();
  {
    std::ofstream out(dir / "displacement.csv");
    out << "node,x,y,z,ux,uy,uz\n" << std::setprecision(17);
    for (std::size_t i = 0; i < x.size(); ++i) {
      out << i << ',' << x[i].x() << ',' << x[i].y() << ',' << x[i].z() << ',' << r.u_m[3 * i]
          << ',' << r.u_m[3 * i + 1] << ',' << r.u_m[3 * i + 2] << '\n';
    }
    if (!out) throw std::runtime_error((dir / "displacement.csv").string() + ": write failed");
  }
  {
    std::ofstream out(dir / "reactions.csv");
    out << "node,x,y,z,rx,ry,rz\n" << std::setprecision(17);
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (!r.constrained[i]) continue;
      out << i << ',' << x[i].x() << ',' << x[i].y() << ',' << x[i].z() << ','
          << r.reaction_n[3 * i] << ',' << r.reaction_n[3 * i + 1] << ',' << r.reaction_n[3 * i + 2]
          << '\n';
    }
    if (!out) throw std::runtime_error((dir / "reactions.csv").string() + ": write failed");
  }
  std::vector<double> u(r.u_m.data(), r.u_m.data() + r.u_m.size());
  std::vector<double> rf(r.reaction_n.data(), r.reaction_n.data() + r.reaction_n.size());
  std::vector<double> magnitude(x.size());
  std::vector<int> fixed(x.size(), 0);
  for (std::size_t i = 0; i < x.size(); ++i) {
    magnitude[i] = r.u_m.segment<3>(3 * i).norm();
  }
  for (int n : fixed_nodes) fixed[n] = 1;
  neurosim::mesh::write_vtu((dir / "result.vtu").string(), x, mesh.tets(),
                            {neurosim::mesh::VtuField{"displacement_m", 3, u},
                             neurosim::mesh::VtuField{"reaction_n", 3, rf},
                             neurosim::mesh::make_field("displacement_magnitude_m", magnitude),
                             neurosim::mesh::make_field("fixed", fixed)},
                            {neurosim::mesh::make_field("label", mesh.tet_labels())});
}

// Loads and prescribed displacements of one mesh (mesh: the one node ids refer to).
struct Held {
  Vec3 displacement_m{Vec3::Zero()};  // unit m, the held components only
  std::array<bool, 3> components{{false, false, false}};
};
struct MeshLoads {
  Eigen::VectorXd f;          // 3N, unit N
  std::map<int, Held> prescribed;  // node -> held components and their displacement
  int count{0};               // scene entries on this mesh

  // The held components as prescribed sets (one per node), as the fem solvers take them.
  std::vector<neurosim::fem::PrescribedDofs> held() const {
    std::vector<neurosim::fem::PrescribedDofs> out;
    for (const auto& [node, hold] : prescribed) {
      out.push_back(neurosim::fem::PrescribedDofs{{node}, hold.displacement_m, hold.components});
    }
    return out;
  }
};

MeshLoads gather_loads(const neurosim::scene::Model& model, int mesh_index) {
  MeshLoads out;
  const auto& mesh = model.meshes[static_cast<std::size_t>(mesh_index)].mesh;
  out.f = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(mesh.num_vertices()));
  for (const auto& l : model.loads) {
    if (l.mesh != mesh_index) continue;
    ++out.count;
    for (int node : l.nodes) out.f.segment<3>(3 * node) += l.force_per_node_n;
  }
  for (const auto& p : model.prescribed) {
    if (p.mesh != mesh_index) continue;
    ++out.count;
    for (int node : p.nodes) {
      Held& h = out.prescribed[node];
      for (int a = 0; a < 3; ++a) {
        if (!p.components[a]) continue;
        h.components[a] = true;
        h.displacement_m[a] = p.displacement_m[a];
      }
    }
  }
  return out;
}

// Summary lines shared by both paths: largest displacement, equilibrium of the supports.
void print_summary(const MeshResult& r, const Eigen::VectorXd& f,
                   const std::map<int, Held>& prescribed) {
  Vec3 total_load = Vec3::Zero(), total_reaction = Vec3::Zero(), prescribed_reaction = Vec3::Zero();
  for (const auto& [node, disp] : prescribed) {
    (void)disp;
    prescribed_reaction += r.reaction_n.segment<3>(3 * node);
  }
  double max_u = 0.0;
  int max_node = 0;
  const int n = static_cast<int>(r.u_m.size() / 3);
  for (int i = 0; i < n; ++i) {
    if (f.size() > 0) total_load += f.segment<3>(3 * i);
    total_reaction += r.reaction_n.segment<3>(3 * i);
    const double ui = r.u_m.segment<3>(3 * i).norm();
    if (ui > max_u) {
      max_u = ui;
      max_node = i;
    }
  }
  std::cout << std::setprecision(6) << "  max |u| = " << max_u << " m at node " << max_node
            << "\n  total load = (" << total_load.transpose() << ") N, total reaction = ("
            << total_reaction.transpose()
            << ") N, imbalance = " << (total_load + total_reaction).norm() << " N\n";
  if (!prescribed.empty()) {
    std::cout << "  force the prescribed nodes (" << prescribed.size() << ") exert on the body = ("
              << prescribed_reaction.transpose() << ") N\n";
  }
}

// One mesh on its own (no coupling): factor, solve, reactions at fixed and prescribed nodes.
MeshResult solve_alone(const neurosim::scene::LoadedMesh& lm, const MeshLoads& loads) {
  const int n = static_cast<int>(lm.mesh.num_vertices());
  const auto t1 = std::chrono::steady_clock::now();
  neurosim::fem::StaticSolver solver(lm.mesh, lm.materials, lm.fixed_nodes);
  const double factor_s = seconds_since(t1);
  const auto t2 = std::chrono::steady_clock::now();
  MeshResult r;
  r.constrained.assign(n, 0);
  for (int node : lm.fixed_nodes) r.constrained[node] = 1;
  if (loads.prescribed.empty()) {
    r.u_m = solver.solve(loads.f);
    // Reactions at the supports: K u - f at fixed nodes.
    Eigen::VectorXd residual = solver.stiffness() * r.u_m - loads.f;
    r.reaction_n = Eigen::VectorXd::Zero(3 * n);
    for (int node : lm.fixed_nodes)
      r.reaction_n.segment<3>(3 * node) = residual.segment<3>(3 * node);
  } else {
    // Held components only; the others stay free unknowns.
    for (const auto& [node, hold] : loads.prescribed) r.constrained[node] = 1;
    auto sol = solver.solve_prescribed_dofs(loads.held(), loads.f);
    r.u_m = std::move(sol.displacement_m);
    r.reaction_n = std::move(sol.reaction_n);
  }
  const double solve_s = seconds_since(t2);
  const auto& info = solver.factor_info();
  std::cout << std::setprecision(6) << "  factor " << info.num_free_dofs << " dofs in " << factor_s
            << " s (nnz(L) = " << info.factor_nnz << "), solve " << solve_s << " s\n";
  return r;
}

// Newton's residual per increment and a summary line.
void print_newton(const neurosim::fem::EquilibriumResult& sol, neurosim::fem::Tier tier,
                  const neurosim::fem::NewtonOptions& options, double solve_s) {
  int iterations = 0;
  for (std::size_t i = 0; i < sol.increments.size(); ++i) {
    const auto& inc = sol.increments[i];
    iterations += static_cast<int>(inc.residual_n.size()) - 1;
    std::cout << "  increment " << i + 1 << " load factor " << std::setprecision(4)
              << inc.load_factor << ": Newton residual (N)";
    for (double res : inc.residual_n) std::cout << ' ' << std::setprecision(3) << res;
    if (inc.cutbacks > 0) std::cout << " (after " << inc.cutbacks << " cutback(s))";
    if (inc.predicted) std::cout << " (tangent predictor)";
    if (inc.projected_iterations > 0) {
      std::cout << " (" << inc.projected_iterations << " projected-tangent step(s))";
    }
    std::cout << '\n';
  }
  std::cout << std::setprecision(6) << "  " << neurosim::fem::tier_name(tier) << ": "
            << sol.increments.size() << " increments, " << iterations
            << " Newton iterations, tolerance " << options.tolerance * sol.force_scale_n
            << " N, largest strain " << sol.elements.max_strain << ", "
            << sol.elements.clamped_elements << " clamped / " << sol.elements.inverted_elements
            << " inverted elements; solve " << solve_s << " s\n";
}

// Newton for an offline solve (both tier paths). The answer is converged to the default
// tolerance at load factor 1 either way; these only change the work on the way (solve_bench,
// bench/RESULTS.md "Nonlinear static solve against CalculiX": 2.8x fewer CPU seconds on the
// brain pressed 10 mm): chord steps with the last factorized tangent, Anderson-accelerated,
// refactorizing only when a step contracts the residual by less than half
// (NewtonOptions::reuse_factorization), and the increments before the last converged to 1e-4
// of the force scale only (NewtonOptions::path_tolerance: a hyperelastic answer does not
// depend on how tightly the load path was followed).
neurosim::fem::NewtonOptions offline_newton_options(int increments) {
  neurosim::fem::NewtonOptions o;
  o.increments = increments;
  o.reuse_factorization = true;
  o.path_tolerance = 1e-4;
  o.tangent_predictor = true;
  return o;
}

// One mesh on its own in the corotational or nonlinear tier: Newton with load increments.
MeshResult solve_alone_tier(const neurosim::scene::LoadedMesh& lm, const MeshLoads& loads,
                            neurosim::fem::Tier tier, int increments) {
  const int n = static_cast<int>(lm.mesh.num_vertices());
  MeshResult r;
  r.constrained.assign(n, 0);
  for (int node : lm.fixed_nodes) r.constrained[node] = 1;
  for (const auto& [node, hold] : loads.prescribed) r.constrained[node] = 1;
  const auto t1 = std::chrono::steady_clock::now();
  neurosim::fem::EquilibriumSolver solver(
      {&lm.mesh, lm.materials, tier, lm.fixed_nodes, loads.held(), {}});
  neurosim::fem::NewtonOptions options = offline_newton_options(increments);
  const neurosim::fem::EquilibriumResult sol = solver.solve(loads.f, options);
  const double solve_s = seconds_since(t1);
  print_newton(sol, tier, options, solve_s);
  r.u_m = sol.displacement_m;
  r.reaction_n = sol.reaction_n;
  return r;
}

// A host and the meshes tied to it, solved as one body through the exact coupled compliance
// (interaction::CoupledBody): u = L_c (f + F_P), with the prescribed nodes' forces F_P from the
// 3p x 3p block of L_c at those nodes (one block solve of 3p columns). Reactions at the host's
// constrained nodes are r_A = K_A u_A - f + J^T (K_B u_B)_tied (what the supports add to the
// applied load and to the embedded meshes' pull), at an embedded mesh's fixed nodes r_B = K_B u_B.
struct BodyResult {
  MeshResult host;
  std::vector<std::pair<int, MeshResult>> embedded;  // (mesh index, result)
};

BodyResult solve_body(const neurosim::interaction::Simulation& sim,
                      const neurosim::interaction::CoupledBody& body, const MeshLoads& loads,
                      const std::string& what) {
  const int h = body.host_index();
  const auto& host = sim.mesh(h);
  const int n = static_cast<int>(host.num_vertices());
  const auto& fixed = sim.fixed_nodes(h);
  std::vector<char> is_fixed(n, 0);
  for (int v : fixed) is_fixed[v] = 1;
  for (const auto& [node, disp] : loads.prescribed) {
    (void)disp;
    if (is_fixed[node]) {
      throw std::runtime_error(what + ": node " + std::to_string(node) +
                               " is both fixed (or carved out inside an embedded mesh) and "
                               "prescribed");
    }
  }
  const auto t0 = std::chrono::steady_clock::now();
  BodyResult out;
  MeshResult& r = out.host;
  // Host nodal forces: the loads plus, at the prescribed components, the forces that hold them.
  Eigen::VectorXd forces_n = loads.f;
  if (!loads.prescribed.empty()) {
    std::vector<int> dofs;  // the held components only (the others stay free)
    std::vector<double> held;
    for (const auto& [node, hold] : loads.prescribed) {
      for (int a = 0; a < 3; ++a) {
        if (!hold.components[a]) continue;
        dofs.push_back(3 * node + a);
        held.push_back(hold.displacement_m[a]);
      }
    }
    const int p3 = static_cast<int>(dofs.size());
    const Eigen::VectorXd d = Eigen::Map<const Eigen::VectorXd>(held.data(), p3);
    Eigen::MatrixXd unit = Eigen::MatrixXd::Zero(3 * n, p3), columns;  // E_P, L_c E_P
    for (int j = 0; j < p3; ++j) unit(dofs[j], j) = 1.0;
    body.coupled_displacement(unit, columns);
    Eigen::VectorXd u_loads;
    body.coupled_displacement(loads.f, u_loads);
    Eigen::MatrixXd block(p3, p3);
    Eigen::VectorXd gap(p3);
    for (int i = 0; i < p3; ++i) {
      block.row(i) = columns.row(dofs[i]);
      gap[i] = d[i] - u_loads[dofs[i]];
    }
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(0.5 * (block + block.transpose()));
    if (ldlt.info() != Eigen::Success || !ldlt.isPositive() || ldlt.vectorD().minCoeff() <= 0.0) {
      throw std::runtime_error(what +
                               ": the compliance at the prescribed nodes is singular (a "
                               "prescribed node that cannot move?)");
    }
    const Eigen::VectorXd held_n = ldlt.solve(gap);
    for (int j = 0; j < p3; ++j) forces_n[dofs[j]] += held_n[j];
  }
  // Fields of the host and its tied meshes for these forces: the implementation the server's
  // field thread uses (one coupled solve, tied meshes from the host field).
  neurosim::interaction::FieldSnapshot snapshot;
  sim.snapshot(snapshot);
  auto& forces_on_body = snapshot.bodies.at(static_cast<std::size_t>(sim.body_index(h)));
  forces_on_body.slots.clear();
  forces_on_body.forces_n.clear();
  forces_on_body.nodal_forces_n = forces_n;
  sim.displacements(snapshot, h, r.u_m);
  // Embedded meshes and the forces they put on the host.
  Eigen::VectorXd coupling_on_host = Eigen::VectorXd::Zero(3 * n);
  const auto& ties = body.ties();
  for (std::size_t t = 0; t < ties.size(); ++t) {
    const auto& tie = ties[t];
    MeshResult rb;
    sim.displacements(snapshot, tie.mesh(), rb.u_m);
    const auto k_b = neurosim::fem::assemble_stiffness(
        tie.geometry(), neurosim::fem::MaterialMap::uniform(tie.material()));
    const Eigen::VectorXd internal = k_b * rb.u_m;  // force B's elements need at its nodes
    const int nb = static_cast<int>(tie.geometry().num_vertices());
    rb.constrained.assign(nb, 0);
    rb.reaction_n = Eigen::VectorXd::Zero(3 * nb);
    for (int v : tie.fixed_nodes()) {
      rb.constrained[v] = 1;
      rb.reaction_n.segment<3>(3 * v) = internal.segment<3>(3 * v);
    }
    for (std::size_t k = 0; k < tie.tied_nodes().size(); ++k) {
      const Vec3 pull = internal.segment<3>(3 * tie.tied_nodes()[k]);  // A holds B with this
      for (int a = 0; a < 3; ++a) {
        const int node = tie.host_nodes()[k][a];
        coupling_on_host.segment<3>(3 * node) -= tie.weights()[k][a] * pull;
      }
    }
    const double residual = tie.residual(r.u_m, rb.u_m);
    std::cout << std::setprecision(6) << "  tied: " << sim.mesh_id(tie.mesh()) << " ("
              << tie.tied_nodes().size() << " surface nodes on " << body.boundary_nodes().size()
              << " nodes of S'), tie residual max |u_A - u_B| = " << residual << " m\n";
    out.embedded.emplace_back(tie.mesh(), std::move(rb));
  }
  // Reactions at the host's fixed and prescribed nodes; everywhere else the residual is the
  // solution's equilibrium error, reported.
  const Eigen::VectorXd residual =
      body.host_solver().stiffness() * r.u_m - loads.f - coupling_on_host;
  r.constrained.assign(n, 0);
  r.reaction_n = Eigen::VectorXd::Zero(3 * n);
  for (int v : fixed) r.constrained[v] = 1;
  for (const auto& [node, disp] : loads.prescribed) {
    (void)disp;
    r.constrained[node] = 1;
  }
  double free_residual = 0.0, scale = loads.f.lpNorm<Eigen::Infinity>();
  for (int v = 0; v < n; ++v) {
    if (r.constrained[v]) {
      r.reaction_n.segment<3>(3 * v) = residual.segment<3>(3 * v);
      scale = std::max(scale, residual.segment<3>(3 * v).norm());
    } else {
      free_residual = std::max(free_residual, residual.segment<3>(3 * v).norm());
    }
  }
  if (!r.u_m.allFinite() || !r.reaction_n.allFinite()) {
    throw std::runtime_error(what + ": solution is not finite");
  }
  std::cout << std::setprecision(6) << "  coupled solve " << seconds_since(t0)
            << " s; equilibrium residual at free nodes " << free_residual << " N (largest "
            << "nodal load or reaction " << scale << " N)\n";
  return out;
}

// A host and its tied meshes in the corotational or nonlinear tier: one Newton solve of all
// meshes with the ties eliminated exactly (fem::EquilibriumSolver, u = T q), on the server's
// carved host and coupling map. Reactions at every constrained node of every mesh.
BodyResult solve_body_tier(const neurosim::interaction::Simulation& sim,
                           const neurosim::interaction::CoupledBody& body,
                           const neurosim::fem::Material& host_material, const MeshLoads& loads,
                           neurosim::fem::Tier tier, int increments) {
  const int h = body.host_index();
  neurosim::fem::EquilibriumDefinition def = neurosim::interaction::equilibrium_definition(
      body, host_material, sim.fixed_nodes(h), tier);
  def.prescribed = loads.held();
  neurosim::fem::EquilibriumSolver solver(def);
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver.num_dofs());
  f.head(loads.f.size()) = loads.f;
  neurosim::fem::NewtonOptions options = offline_newton_options(increments);
  const auto t0 = std::chrono::steady_clock::now();
  const neurosim::fem::EquilibriumResult sol = solver.solve(f, options);
  print_newton(sol, tier, options, seconds_since(t0));
  BodyResult out;
  auto slice = [&](int b, const std::vector<int>& constrained_nodes, MeshResult& r) {
    const int nb = solver.body_forces(b).num_dofs();
    r.u_m = sol.displacement_m.segment(solver.body_offset(b), nb);
    r.reaction_n = sol.reaction_n.segment(solver.body_offset(b), nb);
    r.constrained.assign(static_cast<std::size_t>(nb / 3), 0);
    for (int v : constrained_nodes) r.constrained[static_cast<std::size_t>(v)] = 1;
  };
  std::vector<int> host_constrained = def.fixed_nodes;
  for (const auto& [node, hold] : loads.prescribed) host_constrained.push_back(node);
  slice(0, host_constrained, out.host);
  const auto& ties = body.ties();
  for (std::size_t t = 0; t < ties.size(); ++t) {
    MeshResult rb;
    slice(static_cast<int>(t) + 1, ties[t].fixed_nodes(), rb);
    std::cout << std::setprecision(6) << "  tied: " << sim.mesh_id(ties[t].mesh()) << " ("
              << ties[t].tied_nodes().size() << " surface nodes), tie residual max |u_A - u_B| = "
              << ties[t].residual(out.host.u_m, rb.u_m) << " m\n";
    out.embedded.emplace_back(ties[t].mesh(), std::move(rb));
  }
  return out;
}

void print_mesh_header(const std::string& id, const neurosim::mesh::TetMesh& mesh,
                       std::size_t num_fixed, const neurosim::fem::Material& material,
                       double load_s) {
  const auto q = neurosim::mesh::quality(mesh);
  std::cout << "mesh " << id << ": " << mesh.num_vertices() << " vertices, " << mesh.num_tets()
            << " tetrahedra, " << num_fixed << " fixed nodes; E = " << material.youngs_modulus_pa
            << " Pa, nu = " << material.poisson_ratio << "; load " << std::fixed
            << std::setprecision(3) << load_s << " s\n"
            << std::defaultfloat << "  quality: " << q.summary() << "\n";
}

// A solved displacement larger than this many times the scene's size is refused.
constexpr double kMaxDisplacementToSceneSize = 100.0;

// Diagonal of the bounding box of every mesh of the scene, unit m.
double scene_diagonal_m(const neurosim::scene::Model& model) {
  Vec3 lo = Vec3::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& lm : model.meshes) {
    Vec3 a, b;
    lm.mesh.bounds(a, b);
    lo = lo.cwiseMin(a);
    hi = hi.cwiseMax(b);
  }
  return (hi - lo).norm();
}

void check_plausible(const MeshResult& r, double scene_size_m, const std::string& what) {
  if (!r.u_m.allFinite() || !r.reaction_n.allFinite())
    throw std::runtime_error(what + ": solution is not finite");
  double max_u = 0.0;
  int max_node = 0;
  for (int i = 0; i < static_cast<int>(r.u_m.size() / 3); ++i) {
    const double ui = r.u_m.segment<3>(3 * i).norm();
    if (ui > max_u) {
      max_u = ui;
      max_node = i;
    }
  }
  if (max_u > kMaxDisplacementToSceneSize * scene_size_m) {
    std::ostringstream msg;
    msg << what << ": max |u| = " << max_u << " m at node " << max_node << " is more than "
        << kMaxDisplacementToSceneSize << " times the scene's size (" << scene_size_m
        << " m, bounding-box diagonal): not a solution of this scene (check the material's E, "
        << "the loads and the prescribed displacements)";
    throw std::runtime_error(msg.str());
  }
}

struct RunOptions {
  std::string scene_path, out_dir, only_mesh, tier;  // tier: empty = the scene's
  std::string element;  // empty: the scene's material.element
  bool quiet{false}, uncoupled{false};
  int increments{0};
  double load_timeout_s{900.0};  // loading the scene (meshes read or generated); 0: no limit
};

// f(); std::bad_alloc becomes an error naming what was being built.
template <class F>
auto building(const std::string& what, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const std::bad_alloc&) {
    throw std::runtime_error("out of memory while " + what);
  }
}

int run(const RunOptions& opt) {
  const std::string& scene_path = opt.scene_path;
  const std::string& out_dir = opt.out_dir;
  const std::string& only_mesh = opt.only_mesh;
  const bool quiet = opt.quiet, uncoupled = opt.uncoupled;
  const auto t_start = neurosim::common::Clock::now();
  // The load on a worker thread, bounded by --load-timeout (a mesh path that blocks, a
  // generated mesh far too large for this machine); SIGTERM ends the process as always.
  neurosim::common::LoadWatchDef watch_def;
  watch_def.program = "neurosim-solve";
  watch_def.limit_s = opt.load_timeout_s;
  neurosim::common::LoadWatch watch(watch_def);
  neurosim::scene::Model model = watch.run(
      "loading the scene " + scene_path, [&] { return neurosim::scene::load_model(scene_path); });
  if (!opt.element.empty()) model.set_element(*neurosim::fem::parse_element(opt.element));
  for (const auto& w : model.warnings) std::cerr << "neurosim-solve: warning: " << w << "\n";
  const double load_s = seconds_since(t_start);
  if (!only_mesh.empty() && model.find_mesh(only_mesh) < 0) {
    throw std::invalid_argument(scene_path + ": --mesh " + only_mesh + ": no such mesh");
  }
  neurosim::fem::Tier tier = model.effects.tier;
  if (!opt.tier.empty()) {
    const auto parsed = neurosim::fem::parse_tier(opt.tier);
    if (!parsed) {
      throw std::invalid_argument("--tier " + opt.tier +
                                  ": expected linear, corotational or nonlinear");
    }
    tier = *parsed;
    if (!neurosim::fem::tier_served(tier))
      throw std::invalid_argument("--tier " + opt.tier + ": " + neurosim::fem::kCorotationalWithdrawn);
  }
  std::cout << "scene " << model.name << " (" << scene_path << "), tier "
            << neurosim::fem::tier_name(tier) << (opt.tier.empty() ? " (scene)" : " (--tier)")
            << "\n";
  const int num_meshes = static_cast<int>(model.meshes.size());
  // Per mesh (scene order): the result, the mesh it refers to and its fixed nodes.
  struct Solved {
    bool done{false};
    MeshResult result;
    const neurosim::mesh::TetMesh* mesh{nullptr};
    std::vector<int> fixed;
  };
  std::vector<Solved> solved(static_cast<std::size_t>(num_meshes));

  // Coupled bodies first: the simulation model the server builds (without tools), so the tie,
  // the carving and the coupling map are the server's.
  std::unique_ptr<neurosim::interaction::Simulation> sim;
  std::vector<char> in_body(static_cast<std::size_t>(num_meshes), 0);
  const bool has_couplings = model.effects.coupling && !model.couplings.empty();
  const bool coupled = has_couplings && !uncoupled;
  if (has_couplings && uncoupled && !quiet) {
    std::cout << "note: --uncoupled: the scene's couplings are not applied; every mesh is solved "
                 "on its own\n";
  }
  for (const auto& r : model.rigid) {
    if (!quiet)
      std::cout << "note: mesh " << r.id << " is rigid (" << r.triangles.size()
                << " triangles, an obstacle for tools): not in the solve\n";
  }
  if (coupled) {
    // The coupled body carves the host and runs one material per mesh: tissues with the mesh's
    // E and nu (the same physics) are solved exactly; any other material is refused.
    for (const auto& c : model.couplings)
      for (int mi : {c.host, c.embedded}) {
        const auto& m = model.meshes[static_cast<std::size_t>(mi)];
        if (const neurosim::scene::TissueDef* t = m.tissue_with_other_material())
          throw std::runtime_error(scene_path + ": mesh \"" + m.id + "\", tissue \"" + t->name +
                                   "\": its own material differs from the mesh's: per-tissue "
                                   "materials are not implemented for coupled solves (use "
                                   "--uncoupled)");
      }
    auto static_model = model;
    static_model.effects.tool_contact = false;
    static_model.effects.deformation_output = false;
    static_model.tools.clear();
    const auto t0 = std::chrono::steady_clock::now();
    sim = building(scene_path + ": building the coupled model",
                   [&] { return neurosim::interaction::Simulation::build(static_model); });
    const double build_s = seconds_since(t0);
    for (int m = 0; m < num_meshes; ++m) {
      const auto* body = sim->body_of(m);
      if (body == nullptr || body->host_index() != m) continue;
      const std::string what = scene_path + ": mesh \"" + sim->mesh_id(m) + "\"";
      print_mesh_header(sim->mesh_id(m), sim->mesh(m), sim->fixed_nodes(m).size(),
                        model.meshes[static_cast<std::size_t>(m)].material, load_s + build_s);
      const MeshLoads loads = gather_loads(model, m);
      for (const auto& tie : body->ties()) {
        in_body[static_cast<std::size_t>(tie.mesh())] = 1;
        if (gather_loads(model, tie.mesh()).count > 0) {
          throw std::runtime_error(scene_path + ": mesh \"" + sim->mesh_id(tie.mesh()) +
                                   "\" is tied to \"" + sim->mesh_id(m) +
                                   "\": neurosim-solve takes loads and prescribed displacements "
                                   "on the host only (or use --uncoupled)");
        }
      }
      in_body[static_cast<std::size_t>(m)] = 1;
      std::cout << "  body: host carved to " << sim->mesh(m).num_tets() << " tetrahedra, "
                << body->ties().size() << " tied mesh(es); model built in " << std::fixed
                << std::setprecision(3) << build_s << " s" << std::defaultfloat << "\n";
      if (loads.count == 0) {
        std::cout << "  no load or prescribed displacement: at rest, not solved\n";
        continue;
      }
      BodyResult br = building(what + ": assembling and solving", [&] {
        return tier == neurosim::fem::Tier::kLinear
                   ? solve_body(*sim, *body, loads, what)
                   : solve_body_tier(*sim, *body, model.meshes[static_cast<std::size_t>(m)].material,
                                     loads, tier, opt.increments);
      });
      print_summary(br.host, loads.f, loads.prescribed);
      solved[m] = {true, std::move(br.host), &sim->mesh(m), sim->fixed_nodes(m)};
      for (auto& [mb, rb] : br.embedded) {
        std::cout << "mesh " << sim->mesh_id(mb) << " (tied to " << sim->mesh_id(m) << ")\n";
        print_summary(rb, Eigen::VectorXd(), {});
        solved[mb] = {true, std::move(rb), &sim->mesh(mb), sim->fixed_nodes(mb)};
      }
    }
  }

  // Every other mesh on its own.
  for (int m = 0; m < num_meshes; ++m) {
    if (in_body[static_cast<std::size_t>(m)]) continue;
    const auto& lm = model.meshes[static_cast<std::size_t>(m)];
    const std::string what = scene_path + ": mesh \"" + lm.id + "\"";
    print_mesh_header(lm.id, lm.mesh, lm.fixed_nodes.size(), lm.material, load_s);
    if (coupled) {
      for (const auto& c : model.couplings) {
        if (c.embedded == m && c.kind == neurosim::scene::CouplingKind::kSliding) {
          std::cout << "  note: its SLIDING coupling to " << model.meshes[c.host].id
                    << " is not applied by the static solver; solved on its own\n";
        }
      }
    }
    const MeshLoads loads = gather_loads(model, m);
    if (loads.count == 0 || (!only_mesh.empty() && only_mesh != lm.id)) {
      std::cout << "  no load or prescribed displacement: at rest, not solved\n";
      continue;
    }
    MeshResult r = building(what + ": assembling and solving", [&] {
      return tier == neurosim::fem::Tier::kLinear ? solve_alone(lm, loads)
                                                   : solve_alone_tier(lm, loads, tier, opt.increments);
    });
    if (!r.u_m.allFinite() || !r.reaction_n.allFinite()) {
      throw std::runtime_error(what + ": solution is not finite");
    }
    print_summary(r, loads.f, loads.prescribed);
    solved[m] = {true, std::move(r), &lm.mesh, lm.fixed_nodes};
  }

  // A result that is not finite, or that moves a node by orders of magnitude more than the
  // scene is large, is not a solution of this scene (a material or load far beyond what the
  // meshes can carry, a near-singular system): an error, not results.
  const double scene_size_m = scene_diagonal_m(model);
  for (int m = 0; m < num_meshes; ++m) {
    const auto& s = solved[static_cast<std::size_t>(m)];
    if (!s.done) continue;
    check_plausible(s.result, scene_size_m,
                    scene_path + ": mesh \"" + model.meshes[static_cast<std::size_t>(m)].id + "\"");
  }

  bool primary_written = false;
  for (int m = 0; m < num_meshes; ++m) {
    const auto& s = solved[static_cast<std::size_t>(m)];
    if (!s.done) continue;
    const std::string& id = model.meshes[static_cast<std::size_t>(m)].id;
    write_outputs(fs::path(out_dir) / id, *s.mesh, s.fixed, s.result);
    if (!primary_written && (only_mesh.empty() || only_mesh == id)) {
      for (const char* name : {"displacement.csv", "reactions.csv", "result.vtu"}) {
        fs::copy_file(fs::path(out_dir) / id / name, fs::path(out_dir) / name,
                      fs::copy_options::overwrite_existing);
      }
      primary_written = true;
    }
  }
  if (!primary_written) {
    throw std::runtime_error(scene_path +
                             ": nothing to solve (no loads or prescribed displacements" +
                             (only_mesh.empty() ? std::string(")") : " on " + only_mesh + ")"));
  }
  std::cout << "results in " << fs::absolute(out_dir).string() << " (" << std::setprecision(3)
            << seconds_since(t_start) << " s total)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  RunOptions opt;
  neurosim::cli::Parser cli("neurosim-solve", kDescription);
  cli.add_option("--scene", opt.scene_path, "scene file")->required();
  cli.add_option("--out", opt.out_dir, "output folder DIR")->required();
  cli.add_option("--mesh", opt.only_mesh, "the mesh copied to the top of DIR");
  cli.add_option("--tier", opt.tier, "linear | nonlinear (default: the scene's)")
      ->check(neurosim::cli::one_of_ignore_case({"linear", "corotational", "nonlinear"}));
  cli.add_option("--element", opt.element,
                 "smoothed-tet | anp-tet | linear-tet: every mesh's element (default: the scene's "
                 "material.element)")
      ->check(neurosim::cli::one_of({"smoothed-tet", "anp-tet", "linear-tet"}));
  cli.add_option("--increments", opt.increments,
                 "initial load increments of the corotational / nonlinear solve (0: automatic)")
      ->check(neurosim::cli::range(0, 100000));
  cli.add_flag("--uncoupled", opt.uncoupled, "every mesh on its own");
  cli.add_option("--load-timeout", opt.load_timeout_s,
                 "give up (exit 1, naming the scene) when loading the scene (reading or "
                 "generating its meshes) takes longer than S seconds; 0: no limit")
      ->capture_default_str()
      ->check(neurosim::cli::range(0.0, 1e6));
  cli.add_flag("--quiet", opt.quiet, "less output");
  cli.footer(kFooter);
  if (auto rc = cli.parse(argc, argv)) return *rc;
  // One thread means one: CHOLMOD's OpenMP regions follow OMP_NUM_THREADS (the solves run on
  // this thread).
  neurosim::fem::cholmod_threads_follow_omp_num_threads();
  try {
    return run(opt);
  } catch (const std::exception& e) {
    std::cerr << "neurosim-solve: error: " << e.what() << "\n";
    return 1;
  }
}
