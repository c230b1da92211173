// neurosim-solve: linear static solve of a scene (loads and prescribed displacements).
// Writes, per solved mesh, displacement.csv, reactions.csv and result.vtu; the first solved
// mesh (or --mesh ID) also at the top of --out, which is what verification scripts read.
#include "server/fem/static_solver.hpp"
#include "server/mesh/quality.hpp"
#include "server/mesh/vtu.hpp"
#include "server/scene/scene.hpp"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <string>

namespace fs = std::filesystem;
using neurosim::mesh::Vec3;

namespace {

void usage(std::ostream& out) {
  out << "usage: neurosim-solve --scene FILE --out DIR [--mesh ID] [--quiet]\n"
         "  Linear static solve of every mesh the scene loads or constrains (SI units).\n"
         "  Writes DIR/<mesh>/{displacement.csv,reactions.csv,result.vtu} and copies the\n"
         "  first solved mesh (or --mesh ID) to DIR/displacement.csv, DIR/reactions.csv,\n"
         "  DIR/result.vtu. CSV headers: node,x,y,z,ux,uy,uz and node,x,y,z,rx,ry,rz.\n";
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct MeshResult {
  Eigen::VectorXd u_m;
  Eigen::VectorXd reaction_n;
  std::vector<char> constrained;  // per node
};

void write_outputs(const fs::path& dir, const neurosim::scene::LoadedMesh& lm,
                   const MeshResult& r) {
  fs::create_directories(dir);
  const auto& x = lm.mesh.vertices();
  {
    std::ofstream out(dir / "displacement.csv");
    out << "node,x,y,z,ux,uy,uz\n" << std::setprecision(17);
    for (std::size_t i = 0; i < x.size(); ++i) {
      out << i << ',' << x[i].x() << ',' << x[i].y() << ',' << x[i].z() << ','
          << r.u_m[3 * i] << ',' << r.u_m[3 * i + 1] << ',' << r.u_m[3 * i + 2] << '\n';
    }
    if (!out) throw std::runtime_error((dir / "displacement.csv").string() + ": write failed");
  }
  {
    std::ofstream out(dir / "reactions.csv");
    out << "node,x,y,z,rx,ry,rz\n" << std::setprecision(17);
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (!r.constrained[i]) continue;
      out << i << ',' << x[i].x() << ',' << x[i].y() << ',' << x[i].z() << ','
          << r.reaction_n[3 * i] << ',' << r.reaction_n[3 * i + 1] << ','
          << r.reaction_n[3 * i + 2] << '\n';
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
  for (int n : lm.fixed_nodes) fixed[n] = 1;
  neurosim::mesh::write_vtu(
      (dir / "result.vtu").string(), x, lm.mesh.tets(),
      {neurosim::mesh::VtuField{"displacement_m", 3, u}, neurosim::mesh::VtuField{"reaction_n", 3, rf},
       neurosim::mesh::make_field("displacement_magnitude_m", magnitude),
       neurosim::mesh::make_field("fixed", fixed)},
      {neurosim::mesh::make_field("label", lm.mesh.tet_labels())});
}

int run(int argc, char** argv) {
  std::string scene_path, out_dir, only_mesh;
  bool quiet = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    if (a == "--scene") scene_path = value();
    else if (a == "--out") out_dir = value();
    else if (a == "--mesh") only_mesh = value();
    else if (a == "--quiet") quiet = true;
    else if (a == "-h" || a == "--help") { usage(std::cout); return 0; }
    else throw std::invalid_argument("unknown argument " + a);
  }
  if (scene_path.empty() || out_dir.empty()) {
    usage(std::cerr);
    return 2;
  }
  const auto t_start = std::chrono::steady_clock::now();
  const auto scene = neurosim::scene::read_scene(scene_path);
  const fs::path scene_dir = fs::path(scene_path).parent_path();
  if (!only_mesh.empty() && neurosim::scene::find_mesh(scene, only_mesh) < 0) {
    throw std::invalid_argument(scene_path + ": --mesh " + only_mesh + ": no such mesh");
  }
  if (scene.effects().coupling() && !quiet) {
    std::cout << "note: couplings are not applied by the static solver yet; meshes are solved "
                 "independently\n";
  }
  std::cout << "scene " << scene.name() << " (" << scene_path << ")\n";
  bool primary_written = false;
  for (const auto& entry : scene.meshes()) {
    const auto t0 = std::chrono::steady_clock::now();
    auto lm = neurosim::scene::load_mesh(entry, scene_dir, scene_path);
    const double load_s = seconds_since(t0);
    const int n = static_cast<int>(lm.mesh.num_vertices());
    const std::string what = scene_path + ": mesh \"" + lm.id + "\"";
    const auto q = neurosim::mesh::quality(lm.mesh);
    std::cout << "mesh " << lm.id << ": " << n << " vertices, " << lm.mesh.num_tets()
              << " tetrahedra, " << lm.fixed_nodes.size() << " fixed nodes; E = "
              << lm.material.youngs_modulus_pa << " Pa, nu = " << lm.material.poisson_ratio
              << "; load " << std::fixed << std::setprecision(3) << load_s << " s\n"
              << std::defaultfloat << "  quality: " << q.summary() << "\n";

    // Loads and prescribed displacements on this mesh.
    Eigen::VectorXd f = Eigen::VectorXd::Zero(3 * n);
    std::map<int, Vec3> prescribed;
    int num_loads = 0;
    for (int i = 0; i < scene.loads_size(); ++i) {
      const auto& l = scene.loads(i);
      if (l.mesh() != lm.id) continue;
      ++num_loads;
      auto nodes = neurosim::scene::select_nodes(lm.mesh, l.region(),
                                                 scene_path + ": loads[" + std::to_string(i) + "]");
      Vec3 per_node = neurosim::scene::to_vec3(l.force_n());
      if (l.distribution() == neurosim::scene::Load::TOTAL_SPLIT_EQUALLY) {
        per_node /= static_cast<double>(nodes.size());
      }
      for (int node : nodes) f.segment<3>(3 * node) += per_node;
    }
    for (int i = 0; i < scene.prescribed_size(); ++i) {
      const auto& p = scene.prescribed(i);
      if (p.mesh() != lm.id) continue;
      ++num_loads;
      auto nodes = neurosim::scene::select_nodes(
          lm.mesh, p.region(), scene_path + ": prescribed[" + std::to_string(i) + "]");
      for (int node : nodes) prescribed[node] = neurosim::scene::to_vec3(p.displacement_m());
    }
    if (num_loads == 0 || (!only_mesh.empty() && only_mesh != lm.id)) {
      std::cout << "  no load or prescribed displacement: at rest, not solved\n";
      continue;
    }

    const auto t1 = std::chrono::steady_clock::now();
    neurosim::fem::StaticSolver solver(lm.mesh, neurosim::fem::MaterialMap::uniform(lm.material),
                                       lm.fixed_nodes);
    const double factor_s = seconds_since(t1);
    const auto t2 = std::chrono::steady_clock::now();
    MeshResult r;
    r.constrained.assign(n, 0);
    for (int node : lm.fixed_nodes) r.constrained[node] = 1;
    if (prescribed.empty()) {
      r.u_m = solver.solve(f);
      // Reactions at the supports: K u - f at fixed nodes.
      Eigen::VectorXd residual = solver.stiffness() * r.u_m - f;
      r.reaction_n = Eigen::VectorXd::Zero(3 * n);
      for (int node : lm.fixed_nodes) r.reaction_n.segment<3>(3 * node) = residual.segment<3>(3 * node);
    } else {
      std::vector<int> nodes;
      Eigen::VectorXd d(3 * prescribed.size());
      for (const auto& [node, disp] : prescribed) {
        d.segment<3>(3 * nodes.size()) = disp;
        nodes.push_back(node);
        r.constrained[node] = 1;
      }
      auto sol = solver.solve_prescribed(nodes, d, f);
      r.u_m = std::move(sol.displacement_m);
      r.reaction_n = std::move(sol.reaction_n);
    }
    const double solve_s = seconds_since(t2);
    if (!r.u_m.allFinite() || !r.reaction_n.allFinite()) {
      throw std::runtime_error(what + ": solution is not finite");
    }

    // Equilibrium: supports balance the applied loads.
    Vec3 total_load = Vec3::Zero(), total_reaction = Vec3::Zero(), prescribed_reaction = Vec3::Zero();
    for (const auto& [node, disp] : prescribed) {
      (void)disp;
      prescribed_reaction += r.reaction_n.segment<3>(3 * node);
    }
    double max_u = 0.0;
    int max_node = 0;
    for (int i = 0; i < n; ++i) {
      total_load += f.segment<3>(3 * i);
      total_reaction += r.reaction_n.segment<3>(3 * i);
      const double ui = r.u_m.segment<3>(3 * i).norm();
      if (ui > max_u) { max_u = ui; max_node = i; }
    }
    const auto& info = solver.factor_info();
    std::cout << std::setprecision(6) << "  factor " << info.num_free_dofs << " dofs in "
              << factor_s << " s (nnz(L) = " << info.factor_nnz << "), solve " << solve_s
              << " s\n  max |u| = " << max_u << " m at node " << max_node
              << "\n  total load = (" << total_load.transpose() << ") N, total reaction = ("
              << total_reaction.transpose() << ") N, imbalance = "
              << (total_load + total_reaction).norm() << " N\n";
    if (!prescribed.empty()) {
      std::cout << "  force the prescribed nodes (" << prescribed.size()
                << ") exert on the body = (" << prescribed_reaction.transpose() << ") N\n";
    }

    write_outputs(fs::path(out_dir) / lm.id, lm, r);
    if (!primary_written && (only_mesh.empty() || only_mesh == lm.id)) {
      for (const char* name : {"displacement.csv", "reactions.csv", "result.vtu"}) {
        fs::copy_file(fs::path(out_dir) / lm.id / name, fs::path(out_dir) / name,
                      fs::copy_options::overwrite_existing);
      }
      primary_written = true;
    }
  }
  if (!primary_written) {
    throw std::runtime_error(scene_path + ": nothing to solve (no loads or prescribed displacements)");
  }
  std::cout << "results in " << fs::absolute(out_dir).string() << " (" << std::setprecision(3)
            << seconds_since(t_start) << " s total)\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << "neurosim-solve: error: " << e.what() << "\n";
    return 1;
  }
}
