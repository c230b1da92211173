// solve_bench: the offline nonlinear static solve against the reference it is checked against.
// For each press depth the scene's prescribed displacement (the probe's footprint on the brain)
// is scaled to that depth, then
//   neurosim-solve --scene DIR/pressD.scene --tier nonlinear --uncoupled --mesh brain
//                  --element linear-tet --out ...
// and CalculiX (ccx, one thread: OMP_NUM_THREADS=1, *HYPERELASTIC NEO HOOKE, NLGEOM, C3D4 on the
// same mesh, same fixed and prescribed nodes, fem::run_calculix) run one after the other, both
// with the scene's material and the linear tetrahedron (C3D4 = linear-tet, whatever element the
// scene names). Both
// start from 4 equal load increments. Printed per depth: wall and CPU seconds of each process
// (CPU: getrusage of the children, what load on the machine does not inflate), the speed-up
// ccx / neurosim (CPU), Newton increments/iterations, and the agreement
// disp_rel_diff = max_i |u_ns - u_ccx| / max_i |u_ccx| over the nodes, force_rel_diff = |sum of
// the reactions at the prescribed nodes, ns - ccx| / |ccx's|.
#include "common/cli.hpp"
#include "server/fem/calculix.hpp"
#include "server/fem/element.hpp"
#include "server/scene/compile.hpp"
#include "server/scene/scene.hpp"
#include "scene.pb.h"

#include <google/protobuf/text_format.h>
#include <sys/resource.h>

#include <Eigen/Core>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

double children_cpu_s() {
  rusage u{};
  getrusage(RUSAGE_CHILDREN, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// neurosim-solve's displacement.csv: node,x,y,z,ux,uy,uz.
Eigen::VectorXd read_displacements(const fs::path& file, std::size_t nodes) {
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(nodes));
  std::size_t count = 0;
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
    if (v.size() != 7) throw std::runtime_error(file.string() + ": bad line " + line);
    const auto i = static_cast<Eigen::Index>(v[0]);
    u.segment<3>(3 * i) << v[4], v[5], v[6];
    ++count;
  }
  if (count != nodes) throw std::runtime_error(file.string() + ": " + std::to_string(count) +
                                               " nodes, expected " + std::to_string(nodes));
  return u;
}

// neurosim-solve's reactions.csv: node,x,y,z,rx,ry,rz (constrained nodes).
Eigen::Vector3d sum_reactions(const fs::path& file, const std::vector<int>& nodes) {
  std::ifstream in(file);
  std::string line;
  std::getline(in, line);
  std::vector<char> want;
  for (int n : nodes) {
    if (n >= static_cast<int>(want.size())) want.resize(n + 1, 0);
    want[n] = 1;
  }
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  while (std::getline(in, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<double> v;
    while (std::getline(ss, cell, ',')) v.push_back(std::stod(cell));
    const int n = static_cast<int>(v.at(0));
    if (n < static_cast<int>(want.size()) && want[n]) s += Eigen::Vector3d(v[4], v[5], v[6]);
  }
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_path = std::string(NEUROSIM_SOURCE_DIR) + "/scenes/brain_artery.scene";
  std::string work = "/tmp/neurosim_solve_bench", mesh_id = "brain";
  std::vector<double> depths_mm;
  bool csv = false;
  int increments = 4;
  neurosim::cli::Parser p("solve_bench",
                          "neurosim-solve --tier nonlinear against CalculiX on one thread, the "
                          "scene's press scaled to each depth.");
  p.add_option("--scene", scene_path, "scene with one prescribed displacement")
      ->capture_default_str();
  p.add_option("--mesh", mesh_id, "the mesh solved (alone, --uncoupled)")->capture_default_str();
  p.add_option("--press-mm", depths_mm, "press depths, unit mm (default 10 and 20)");
  p.add_option("--increments", increments, "initial equal load increments of both solvers")
      ->capture_default_str();
  p.add_option("--work", work, "work folder")->capture_default_str();
  p.add_flag("--csv", csv, "CSV instead of a table");
  if (auto rc = p.parse(argc, argv)) return *rc;
  if (depths_mm.empty()) depths_mm = {10.0, 20.0};
  try {
    fs::create_directories(work);
    const fs::path scene_abs = fs::absolute(scene_path);
    neurosim::scene::Scene base = neurosim::scene::read_scene(scene_abs);
    if (base.prescribed_size() != 1)
      throw std::runtime_error(scene_path + ": needs exactly one prescribed displacement");
    for (auto& m : *base.mutable_meshes()) m.set_file((scene_abs.parent_path() / m.file()).string());
    const auto& d0 = base.prescribed(0).displacement_m();
    const Eigen::Vector3d dir = Eigen::Vector3d(d0.x(), d0.y(), d0.z()).normalized();
    if (csv) {
      std::cout << "press_mm,ns_wall_s,ns_cpu_s,ns_increments,ns_iterations,ccx_wall_s,ccx_cpu_s,"
                   "speedup_cpu,disp_rel_diff,force_rel_diff\n";
    } else {
      std::cout << "press_mm | neurosim-solve wall_s cpu_s incr iter | ccx wall_s cpu_s | "
                   "speed-up (cpu) | disp_rel_diff force_rel_diff\n";
    }
    for (double mm : depths_mm) {
      const std::string tag = "press" + std::to_string(static_cast<int>(std::lround(mm)));
      neurosim::scene::Scene s = base;
      auto* d = s.mutable_prescribed(0)->mutable_displacement_m();
      d->set_x(dir.x() * mm * 1e-3);
      d->set_y(dir.y() * mm * 1e-3);
      d->set_z(dir.z() * mm * 1e-3);
      std::string text;
      google::protobuf::TextFormat::PrintToString(s, &text);
      const fs::path sp = fs::path(work) / (tag + ".scene");
      std::ofstream(sp) << text;
      const fs::path out = fs::path(work) / ("ns_" + tag);
      fs::remove_all(out);
      std::ostringstream cmd;
      cmd << "OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 " << NEUROSIM_BIN_DIR
          << "/neurosim-solve --scene '" << sp.string() << "' --tier nonlinear --uncoupled --mesh "
          << mesh_id << " --element linear-tet --increments " << increments << " --out '" << out.string() << "' > '"
          << out.string() << ".log' 2>&1";
      double cpu0 = children_cpu_s();
      auto t0 = std::chrono::steady_clock::now();
      if (std::system(cmd.str().c_str()) != 0)
        throw std::runtime_error("neurosim-solve failed: " + slurp(out.string() + ".log"));
      const double ns_wall =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double ns_cpu = children_cpu_s() - cpu0;
      const std::string log = slurp(out.string() + ".log");
      std::smatch m;
      int inc = -1, iters = -1;
      if (std::regex_search(log, m, std::regex("(\\d+) increments, (\\d+) Newton iterations"))) {
        inc = std::stoi(m[1]);
        iters = std::stoi(m[2]);
      }

      neurosim::scene::Model model = neurosim::scene::compile(s, sp.string());
      model.set_element(neurosim::fem::Element::kLinearTet);  // what C3D4 is
      const int mi = model.find_mesh(mesh_id);
      if (mi < 0) throw std::runtime_error("no mesh " + mesh_id);
      const auto& lm = model.meshes[mi];
      neurosim::fem::CalculixLoads loads;
      loads.fixed_nodes = lm.fixed_nodes;
      const auto& pr = model.prescribed.at(0);
      loads.prescribed_nodes = pr.nodes;
      loads.prescribed_displacements_m.resize(3 * static_cast<Eigen::Index>(pr.nodes.size()));
      for (std::size_t k = 0; k < pr.nodes.size(); ++k)
        loads.prescribed_displacements_m.segment<3>(3 * static_cast<Eigen::Index>(k)) =
            pr.displacement_m;
      loads.step.neo_hookean_nlgeom = true;
      loads.step.increments = increments;
      neurosim::fem::CalculixRunOptions ro;
      ro.timeout_s = 3600;
      cpu0 = children_cpu_s();
      t0 = std::chrono::steady_clock::now();
      const auto ccx = neurosim::fem::run_calculix(fs::path(work) / ("ccx_" + tag), tag, lm.mesh,
                                                   lm.materials, loads, ro);
      const double ccx_wall =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double ccx_cpu = children_cpu_s() - cpu0;

      const Eigen::VectorXd u = read_displacements(out / "displacement.csv", lm.mesh.num_vertices());
      double max_ref = 0.0, max_diff = 0.0;
      for (Eigen::Index i = 0; i < u.size() / 3; ++i) {
        max_ref = std::max(max_ref, ccx.displacement_m.segment<3>(3 * i).norm());
        max_diff = std::max(max_diff, (u.segment<3>(3 * i) - ccx.displacement_m.segment<3>(3 * i)).norm());
      }
      const Eigen::Vector3d f_ns = sum_reactions(out / "reactions.csv", pr.nodes);
      Eigen::Vector3d f_ccx = Eigen::Vector3d::Zero();
      for (int n : pr.nodes) f_ccx += ccx.reaction_n.segment<3>(3 * n);
      const double disp_rel = max_diff / max_ref, force_rel = (f_ns - f_ccx).norm() / f_ccx.norm();
      const double speedup = ccx_cpu / ns_cpu;
      if (csv) {
        std::cout << mm << ',' << ns_wall << ',' << ns_cpu << ',' << inc << ',' << iters << ','
                  << ccx_wall << ',' << ccx_cpu << ',' << speedup << ',' << disp_rel << ','
                  << force_rel << "\n";
      } else {
        std::cout << std::fixed << std::setprecision(1) << std::setw(8) << mm << " | "
                  << std::setprecision(2) << std::setw(8) << ns_wall << std::setw(7) << ns_cpu
                  << std::setw(5) << inc << std::setw(5) << iters << " | " << std::setw(8)
                  << ccx_wall << std::setw(7) << ccx_cpu << " | " << std::setw(6) << speedup
                  << "x | " << std::scientific << std::setprecision(2) << disp_rel << "  "
                  << force_rel << std::defaultfloat << "\n";
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "solve_bench: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
