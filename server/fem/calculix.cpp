#include "server/fem/calculix.hpp"

#include <sys/wait.h>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <sstream>
#include <stdexcept>

namespace neurosim::fem {

namespace {

std::string shell_quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    out += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  }
  return out + "'";
}

void check_node(int v, std::size_t n, const char* what) {
  if (v < 0 || static_cast<std::size_t>(v) >= n) {
    throw std::invalid_argument(std::string("write_calculix_input: ") + what + " node " +
                                std::to_string(v) + " out of range");
  }
}

// Writes a comma-separated list of node ids (1-based), 8 per line (ccx reads <= 16 per line).
void write_id_list(std::ostream& out, const std::vector<int>& nodes) {
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    out << nodes[k] + 1 << ((k + 1) % 8 == 0 || k + 1 == nodes.size() ? "\n" : ", ");
  }
}

}  // namespace

void write_calculix_input(const std::filesystem::path& inp_file, const mesh::TetMesh& mesh,
                          const MaterialMap& materials, const CalculixLoads& loads) {
  const std::size_t n = mesh.num_vertices();
  materials.validate(mesh.num_tets());
  if (materials.element() != Element::kLinearTet) {
    // The deck is C3D4, which is linear-tet: another element would be compared with an answer
    // that is not its own.
    const Material& m = materials.materials.front();
    throw std::invalid_argument(std::string("write_calculix_input: material '") + m.name +
                                "' asks for element '" + element_name(m.element) +
                                "'; the CalculiX deck is C3D4, which is 'linear-tet' (no CalculiX "
                                "element is written for '" + element_name(m.element) +
                                "'): set the materials' element to linear-tet to compare with "
                                "C3D4");
  }
  for (int v : loads.fixed_nodes) {
    check_node(v, n, "fixed");
  }
  for (int v : loads.prescribed_nodes) {
    check_node(v, n, "prescribed");
  }
  if (loads.prescribed_displacements_m.size() !=
      3 * static_cast<Eigen::Index>(loads.prescribed_nodes.size())) {
    throw std::invalid_argument(
        "write_calculix_input: need 3 prescribed displacements per prescribed node");
  }
  if (!loads.prescribed_displacements_m.allFinite()) {
    throw std::invalid_argument("write_calculix_input: non-finite prescribed displacement");
  }
  if (loads.forces_n.size() != 0 && loads.forces_n.size() != 3 * static_cast<Eigen::Index>(n)) {
    throw std::invalid_argument("write_calculix_input: forces must be empty or 3N");
  }
  if (!loads.forces_n.allFinite()) {
    throw std::invalid_argument("write_calculix_input: non-finite force");
  }
  if (loads.step.increments < 1 || loads.step.increments > 10000) {
    throw std::invalid_argument("write_calculix_input: step.increments must be in [1, 10000]");
  }
  try {
    expand_prescribed(loads.prescribed_sets, static_cast<int>(n), loads.fixed_nodes);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("write_calculix_input: ") + e.what());
  }
  std::vector<std::vector<int>> set_nodes;  // sorted, unique node ids of each prescribed set
  {
    std::vector<char> per_node(n, 0);
    for (int v : loads.prescribed_nodes) {
      per_node[v] = 1;
    }
    for (std::size_t k = 0; k < loads.prescribed_sets.size(); ++k) {
      std::vector<int> ids = loads.prescribed_sets[k].nodes;
      std::sort(ids.begin(), ids.end());
      ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
      for (int v : ids) {
        if (per_node[v]) {
          throw std::invalid_argument("write_calculix_input: prescribed[" + std::to_string(k) +
                                      "]: node " + std::to_string(v) +
                                      " is also in prescribed_nodes");
        }
      }
      set_nodes.push_back(std::move(ids));
    }
  }

  std::ofstream out(inp_file);
  if (!out) {
    throw std::runtime_error("write_calculix_input: cannot write " + inp_file.string());
  }
  out << std::setprecision(17);
  out << "** neurosim external reference export: " << mesh.source() << ", " << n << " nodes, "
      << mesh.num_tets() << " C3D4\n*NODE, NSET=NALL\n";
  for (std::size_t v = 0; v < n; ++v) {
    const auto& x = mesh.vertices()[v];
    if (!x.allFinite()) {
      throw std::invalid_argument("write_calculix_input: non-finite coordinate at node " +
                                  std::to_string(v));
    }
    out << v + 1 << ", " << x.x() << ", " << x.y() << ", " << x.z() << "\n";
  }
  const std::size_t nm = materials.materials.size();
  std::vector<std::vector<int>> tets_of(nm);
  for (std::size_t t = 0; t < mesh.num_tets(); ++t) {
    tets_of[materials.tet_material.empty() ? 0 : materials.tet_material[t]].push_back(
        static_cast<int>(t));
  }
  for (std::size_t m = 0; m < nm; ++m) {
    if (tets_of[m].empty()) {
      continue;
    }
    out << "*ELEMENT, TYPE=C3D4, ELSET=E" << m << "\n";
    for (int t : tets_of[m]) {
      const auto& tet = mesh.tets()[t];
      out << t + 1 << ", " << tet[0] + 1 << ", " << tet[1] + 1 << ", " << tet[2] + 1 << ", "
          << tet[3] + 1 << "\n";
    }
  }
  for (std::size_t m = 0; m < nm; ++m) {
    if (tets_of[m].empty()) {
      continue;
    }
    const Material& mat = materials.materials[m];
    out << "** material " << m << ": " << mat.name << "\n*MATERIAL, NAME=M" << m << "\n";
    if (loads.step.neo_hookean_nlgeom) {
      const double e = mat.youngs_modulus_pa, nu = mat.poisson_ratio;
      // ccx reads at most 20 characters per number: 13 significant digits fit.
      std::ostringstream line;
      line << std::setprecision(13) << e / (4.0 * (1.0 + nu)) << ", "
           << 6.0 * (1.0 - 2.0 * nu) / e;
      out << "*HYPERELASTIC, NEO HOOKE\n" << line.str() << "\n";
    } else {
      out << "*ELASTIC\n" << mat.youngs_modulus_pa << ", " << mat.poisson_ratio << "\n";
    }
    out << "*SOLID SECTION, ELSET=E" << m << ", MATERIAL=M" << m << "\n";
  }
  std::vector<int> rf_nodes = loads.fixed_nodes;
  rf_nodes.insert(rf_nodes.end(), loads.prescribed_nodes.begin(), loads.prescribed_nodes.end());
  for (const auto& ids : set_nodes) {
    rf_nodes.insert(rf_nodes.end(), ids.begin(), ids.end());
  }
  std::sort(rf_nodes.begin(), rf_nodes.end());
  rf_nodes.erase(std::unique(rf_nodes.begin(), rf_nodes.end()), rf_nodes.end());
  if (!loads.fixed_nodes.empty()) {
    out << "*NSET, NSET=NFIX\n";
    write_id_list(out, loads.fixed_nodes);
  }
  for (std::size_t k = 0; k < set_nodes.size(); ++k) {
    out << "** prescribed[" << k << "]: components "
        << components_string(loads.prescribed_sets[k].components) << "\n*NSET, NSET=NP" << k
        << "\n";
    write_id_list(out, set_nodes[k]);
  }
  if (!rf_nodes.empty()) {
    out << "*NSET, NSET=NRF\n";
    write_id_list(out, rf_nodes);
  }
  if (loads.step.neo_hookean_nlgeom) {
    const double inc = 1.0 / loads.step.increments;
    // Initial increment, step time 1, minimum increment, maximum increment; residual and
    // correction criteria 1e-9 (ccx's defaults 5e-3 / 1e-2 would stop far from converged).
    std::ostringstream line;  // ccx: at most 20 characters per number
    line << std::setprecision(13) << inc << ", 1.0, " << inc * 1e-4 << ", " << inc;
    out << "*STEP, NLGEOM, INC=" << 100 * loads.step.increments << "\n*STATIC\n"
        << line.str() << "\n"
        << "*CONTROLS, PARAMETERS=FIELD\n1e-9, 1e-9\n";
  } else {
    out << "*STEP\n*STATIC\n";
  }
  if (!loads.fixed_nodes.empty()) {
    out << "*BOUNDARY\nNFIX, 1, 3\n";
  }
  if (!loads.prescribed_nodes.empty()) {
    out << "*BOUNDARY\n";
    for (std::size_t k = 0; k < loads.prescribed_nodes.size(); ++k) {
      for (int a = 0; a < 3; ++a) {
        out << loads.prescribed_nodes[k] + 1 << ", " << a + 1 << ", " << a + 1 << ", "
            << loads.prescribed_displacements_m[3 * k + a] << "\n";
      }
    }
  }
  if (!set_nodes.empty()) {
    out << "*BOUNDARY\n";
    for (std::size_t k = 0; k < set_nodes.size(); ++k) {
      const PrescribedDofs& p = loads.prescribed_sets[k];
      for (int a = 0; a < 3; ++a) {
        if (p.components[a]) {
          out << "NP" << k << ", " << a + 1 << ", " << a + 1 << ", " << p.displacement_m[a] << "\n";
        }
      }
    }
  }
  bool any_force = false;
  for (Eigen::Index d = 0; d < loads.forces_n.size(); ++d) {
    if (loads.forces_n[d] == 0.0) {
      continue;
    }
    if (!any_force) {
      out << "*CLOAD\n";
    }
    any_force = true;
    out << d / 3 + 1 << ", " << d % 3 + 1 << ", " << loads.forces_n[d] << "\n";
  }
  out << "*NODE PRINT, NSET=NALL\nU\n";
  if (!rf_nodes.empty()) {
    out << "*NODE PRINT, NSET=NRF, TOTALS=NO\nRF\n";
  }
  out << "*END STEP\n";
  if (!out) {
    throw std::runtime_error("write_calculix_input: write error on " + inp_file.string());
  }
}

CalculixResult read_calculix_dat(const std::filesystem::path& dat_file, std::size_t num_nodes) {
  std::ifstream in(dat_file);
  if (!in) {
    throw std::runtime_error("read_calculix_dat: cannot open " + dat_file.string());
  }
  CalculixResult r;
  r.displacement_m = Eigen::VectorXd::Zero(3 * num_nodes);
  r.reaction_n = Eigen::VectorXd::Zero(3 * num_nodes);
  r.has_reaction.assign(num_nodes, 0);
  std::vector<char> has_u(num_nodes, 0);
  enum class Block { kNone, kU, kRF } block = Block::kNone;
  std::string line;
  int line_no = 0;
  auto fail = [&](const std::string& why) {
    throw std::runtime_error(dat_file.string() + ":" + std::to_string(line_no) + ": " + why +
                             ": '" + line + "'");
  };
  while (std::getline(in, line)) {
    ++line_no;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) {
      continue;
    }
    if (std::isalpha(static_cast<unsigned char>(line[first]))) {
      // Block headers: " displacements (vx,vy,vz) for set NALL and time ..." / " forces (fx,fy,fz)
      // ..."
      if (line.compare(first, 13, "displacements") == 0) {
        block = Block::kU;
        const auto at = line.find("time");
        if (at == std::string::npos || !(std::istringstream(line.substr(at + 4)) >> r.time)) {
          fail("no step time in block header");
        }
      } else if (line.compare(first, 6, "forces") == 0) {
        block = Block::kRF;
      } else {
        block = Block::kNone;
      }
      continue;
    }
    if (block == Block::kNone) {
      continue;
    }
    std::istringstream fields(line);
    long id = 0;
    double v[3];
    if (!(fields >> id >> v[0] >> v[1] >> v[2])) {
      fail("expected 'node value value value'");
    }
    if (id < 1 || static_cast<std::size_t>(id) > num_nodes) {
      fail("node id out of range");
    }
    for (double x : v) {
      if (!std::isfinite(x)) {
        fail("non-finite value");
      }
    }
    const std::size_t node = static_cast<std::size_t>(id - 1);
    Eigen::VectorXd& dst = block == Block::kU ? r.displacement_m : r.reaction_n;
    for (int a = 0; a < 3; ++a) {
      dst[3 * node + a] = v[a];
    }
    (block == Block::kU ? has_u : r.has_reaction)[node] = 1;
  }
  for (std::size_t v = 0; v < num_nodes; ++v) {
    if (!has_u[v]) {
      throw std::runtime_error(dat_file.string() + ": no displacement printed for node " +
                               std::to_string(v + 1) + " (ccx id)");
    }
  }
  return r;
}

CalculixResult run_calculix(const std::filesystem::path& work_dir, const std::string& job,
                            const mesh::TetMesh& mesh, const MaterialMap& materials,
                            const CalculixLoads& loads, const CalculixRunOptions& options) {
  std::filesystem::create_directories(work_dir);
  write_calculix_input(work_dir / (job + ".inp"), mesh, materials, loads);
  const auto dat = work_dir / (job + ".dat");
  std::filesystem::remove(dat);
  const auto log = work_dir / (job + ".log");
  std::ostringstream cmd;
  cmd << "cd " << shell_quote(work_dir.string())
      << " && OMP_NUM_THREADS=1 CCX_NPROC_EQUATION_SOLVER=1 timeout -k 5 "
      << std::max(1.0, options.timeout_s) << " " << shell_quote(options.executable) << " -i "
      << shell_quote(job) << " > " << shell_quote(log.string()) << " 2>&1";
  const int status = std::system(cmd.str().c_str());
  const int code = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : -1;
  auto log_tail = [&]() {
    std::ifstream in(log);
    std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    return all.size() > 1500 ? all.substr(all.size() - 1500) : all;
  };
  if (code == 124 || code == 137) {
    throw std::runtime_error("run_calculix: ccx timed out after " +
                             std::to_string(options.timeout_s) + " s in " + work_dir.string());
  }
  if (code == 127) {
    throw std::runtime_error("run_calculix: '" + options.executable +
                             "' not found (Debian: calculix-ccx)");
  }
  if (code != 0 || !std::filesystem::exists(dat)) {
    throw std::runtime_error("run_calculix: ccx failed (exit " + std::to_string(code) + ") in " +
                             work_dir.string() + ":\n" + log_tail());
  }
  // ccx exits 0 even on some input errors: they show up in the log.
  const std::string tail = log_tail();
  if (tail.find("*ERROR") != std::string::npos) {
    throw std::runtime_error("run_calculix: ccx reported an error in " + work_dir.string() + ":\n" +
                             tail);
  }
  CalculixResult result = read_calculix_dat(dat, mesh.num_vertices());
  if (std::abs(result.time - 1.0) > 1e-9) {
    throw std::runtime_error("run_calculix: ccx stopped at step time " +
                             std::to_string(result.time) + " of 1 in " + work_dir.string() +
                             ":\n" + tail);
  }
  return result;
}

}  // namespace neurosim::fem
