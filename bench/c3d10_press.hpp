// The outside reference of the benches' patch presses: a linear tetrahedral mesh made CalculiX
// C3D10 (a node at the middle of every edge), the patch moved by a prescribed displacement with
// the fixed set held, solved by ccx and read back. Shared by accuracy_bench (the scene's press,
// linear elastic) and press_refinement_bench (the coarse brain's press, linear and NLGEOM).
// Units: m, Pa, N.
#pragma once

#include "server/fem/calculix.hpp"
#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <ostream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace neurosim::bench {

// The mesh with a node at the middle of every edge, CalculiX's C3D10 order (corners, then the
// mid-nodes of edges 12 23 31 14 24 34); the corners keep their ids.
struct QuadraticTets {
  std::vector<Eigen::Vector3d> nodes;
  std::vector<std::array<int, 10>> elements;
  std::map<std::pair<int, int>, int> mid;  // sorted edge -> its mid node
  // The corners and the mid-nodes of every edge between two of them (a held or pressed face
  // stays flat).
  std::vector<int> with_mid(const std::vector<int>& corners) const {
    std::vector<char> in(nodes.size(), 0);
    for (int v : corners) in[static_cast<std::size_t>(v)] = 1;
    std::vector<int> out = corners;
    for (const auto& [edge, id] : mid)
      if (in[static_cast<std::size_t>(edge.first)] && in[static_cast<std::size_t>(edge.second)])
        out.push_back(id);
    return out;
  }
};

inline QuadraticTets quadratic_tets(const mesh::TetMesh& m) {
  QuadraticTets q;
  q.nodes = m.vertices();
  auto mid_node = [&](int a, int b) {
    const auto key = std::minmax(a, b);
    const auto it = q.mid.find(key);
    if (it != q.mid.end()) return it->second;
    const int id = static_cast<int>(q.nodes.size());
    q.nodes.push_back(0.5 * (m.vertices()[static_cast<std::size_t>(a)] +
                             m.vertices()[static_cast<std::size_t>(b)]));
    q.mid.emplace(key, id);
    return id;
  };
  for (const auto& t : m.tets())
    q.elements.push_back({t[0], t[1], t[2], t[3], mid_node(t[0], t[1]), mid_node(t[1], t[2]),
                          mid_node(t[2], t[0]), mid_node(t[0], t[3]), mid_node(t[1], t[3]),
                          mid_node(t[2], t[3])});
  return q;
}

// A sub-model's clamp in C3D10 (sub_model.hpp): the clamped corners and the mid-nodes of the cut
// faces' edges only (not of other edges between two clamped corners: the cut's rim on the
// surface, edges through the inside), so the clamp is exactly the cut surface.
inline std::vector<int> clamp_of_faces(const QuadraticTets& q, const std::vector<int>& corners,
                                       const std::vector<mesh::Tri>& faces) {
  std::vector<char> f(q.nodes.size(), 0);
  for (int v : corners) f[static_cast<std::size_t>(v)] = 1;
  for (const auto& tri : faces)
    for (int k = 0; k < 3; ++k)
      f[static_cast<std::size_t>(q.mid.at(std::minmax(tri[k], tri[(k + 1) % 3])))] = 1;
  std::vector<int> out;
  for (std::size_t v = 0; v < f.size(); ++v)
    if (f[v]) out.push_back(static_cast<int>(v));
  return out;
}

// The deck's *NODE (NSET NALL) and *ELEMENT (C3D10, ELSET EALL) blocks, 1-based ids; and a node
// set (ten ids a line).
inline void write_c3d10_mesh(std::ostream& out, const QuadraticTets& q) {
  out << "*NODE, NSET=NALL\n";
  for (std::size_t v = 0; v < q.nodes.size(); ++v)
    out << v + 1 << ", " << q.nodes[v].x() << ", " << q.nodes[v].y() << ", " << q.nodes[v].z()
        << "\n";
  out << "*ELEMENT, TYPE=C3D10, ELSET=EALL\n";
  for (std::size_t e = 0; e < q.elements.size(); ++e) {
    out << e + 1;
    for (int n : q.elements[e]) out << ", " << n + 1;
    out << "\n";
  }
}
inline void write_node_set(std::ostream& out, const char* name, const std::vector<int>& set) {
  out << "*NSET, NSET=" << name << "\n";
  for (std::size_t i = 0; i < set.size(); ++i)
    out << set[i] + 1 << (i + 1 == set.size() || i % 10 == 9 ? "\n" : ", ");
}

// The press's analysis: linear elastic (*ELASTIC), or NLGEOM neo-Hookean as
// fem::write_calculix_input (C10 = E / (4 (1 + nu)), D1 = 6 (1 - 2 nu) / E) in `increments`
// equal initial increments with *CONTROLS 1e-9.
struct C3d10Press {
  bool nlgeom{false};
  int increments{10};
  double timeout_s{1200.0};  // ccx's wall clock, unit s
};

// Writes DIR/JOB.inp (one material, NFIX = fixed_q held, NPRESS = patch_q moved by
// displacement_m), runs ccx on one thread and reads JOB.dat. Throws naming the deck and the log
// when ccx fails, an NLGEOM step ends early or a patch node has no reaction.
inline fem::CalculixResult run_c3d10_press(const std::filesystem::path& dir,
                                           const std::string& job, const std::string& title,
                                           const QuadraticTets& q, const fem::Material& mat,
                                           const std::vector<int>& fixed_q,
                                           const std::vector<int>& patch_q,
                                           const Eigen::Vector3d& displacement_m,
                                           const C3d10Press& press = {}) {
  namespace fs = std::filesystem;
  fs::create_directories(dir);
  {
    std::ofstream out(dir / (job + ".inp"));
    out.precision(13);  // ccx reads at most 20 characters per number
    out << "** " << title << " " << job << "\n";
    write_c3d10_mesh(out, q);
    const double e = mat.youngs_modulus_pa, nu = mat.poisson_ratio;
    out << "*MATERIAL, NAME=M\n";
    if (press.nlgeom)
      out << "*HYPERELASTIC, NEO HOOKE\n" << e / (4.0 * (1.0 + nu)) << ", "
          << 6.0 * (1.0 - 2.0 * nu) / e << "\n";
    else
      out << "*ELASTIC\n" << e << ", " << nu << "\n";
    out << "*SOLID SECTION, ELSET=EALL, MATERIAL=M\n";
    write_node_set(out, "NFIX", fixed_q);
    write_node_set(out, "NPRESS", patch_q);
    if (press.nlgeom) {
      const double inc = 1.0 / press.increments;
      out << "*STEP, NLGEOM, INC=" << 100 * press.increments << "\n*STATIC\n"
          << inc << ", 1.0, " << inc * 1e-4 << ", " << inc << "\n"
          << "*CONTROLS, PARAMETERS=FIELD\n1e-9, 1e-9\n";
    } else {
      out << "*STEP\n*STATIC\n";
    }
    out << "*BOUNDARY\nNFIX, 1, 3\n";
    for (int a = 0; a < 3; ++a)
      out << "NPRESS, " << a + 1 << ", " << a + 1 << ", " << displacement_m[a] << "\n";
    out << "*NODE PRINT, NSET=NALL\nU\n*NODE PRINT, NSET=NPRESS, TOTALS=NO\nRF\n*END STEP\n";
  }
  fs::remove(dir / (job + ".dat"));
  const std::string cmd = "cd '" + dir.string() +
                          "' && OMP_NUM_THREADS=1 CCX_NPROC_EQUATION_SOLVER=1 timeout -k 5 " +
                          std::to_string(static_cast<long>(press.timeout_s)) + " ccx -i " + job +
                          " > " + job + ".log 2>&1";
  const int status = std::system(cmd.c_str());
  const int code = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : -1;
  if (code != 0)
    throw std::runtime_error("ccx failed on " + (dir / (job + ".inp")).string() + " (exit " +
                             std::to_string(code) + ", log " + (dir / (job + ".log")).string() + ")");
  auto r = fem::read_calculix_dat(dir / (job + ".dat"), q.nodes.size());
  if (press.nlgeom && r.time < 1.0 - 1e-9)
    throw std::runtime_error((dir / (job + ".dat")).string() + ": NLGEOM step ended at time " +
                             std::to_string(r.time));
  for (int v : patch_q)
    if (!r.has_reaction[static_cast<std::size_t>(v)])
      throw std::runtime_error((dir / (job + ".dat")).string() + ": no RF for node " +
                               std::to_string(v + 1));
  return r;
}

}  // namespace neurosim::bench
