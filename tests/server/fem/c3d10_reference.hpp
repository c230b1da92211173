// The external reference of the element tests: CalculiX's quadratic tetrahedra (C3D10) on a
// linear-tetrahedron mesh with a node added at the middle of every edge, linear elastic, under
// nodal loads and/or a node set held at a prescribed displacement (ccx run in a temporary
// directory, one thread, bounded in time). Used by locking_test (a block, a cantilever) and
// brain_press_test (a coarse Colin27 brain).
#pragma once

#include "server/fem/calculix.hpp"
#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>
#include <Eigen/Core>

#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace neurosim::fem::testing {

// The mesh with a node at the middle of every edge: C3D10 connectivity in CalculiX's order
// (corners 1-4, then the mid-nodes of edges 1-2, 2-3, 3-1, 1-4, 2-4, 3-4), 0-based.
struct QuadraticMesh {
  std::vector<mesh::Vec3> nodes;  // the corners first (same ids), then the mid-edge nodes
  std::vector<std::array<int, 10>> elements;
  std::map<std::pair<int, int>, int> mid;  // sorted edge -> its mid node

  // The corner nodes `corners` and the mid-nodes of every edge between two of them (a fixed
  // or pressed face stays flat).
  std::vector<int> with_mid_nodes(const std::vector<int>& corners) const {
    std::vector<char> in(nodes.size(), 0);
    for (int v : corners) in[static_cast<std::size_t>(v)] = 1;
    std::vector<int> out = corners;
    for (const auto& [edge, m] : mid)
      if (in[static_cast<std::size_t>(edge.first)] && in[static_cast<std::size_t>(edge.second)])
        out.push_back(m);
    return out;
  }
};

inline QuadraticMesh quadratic(const mesh::TetMesh& m) {
  QuadraticMesh q;
  q.nodes = m.vertices();
  auto mid_node = [&](int a, int b) {
    const auto key = std::minmax(a, b);
    const auto it = q.mid.find(key);
    if (it != q.mid.end()) return it->second;
    const int id = static_cast<int>(q.nodes.size());
    q.nodes.push_back(0.5 * (m.vertices()[a] + m.vertices()[b]));
    q.mid.emplace(key, id);
    return id;
  };
  for (const mesh::Tet& t : m.tets()) {
    q.elements.push_back({t[0], t[1], t[2], t[3], mid_node(t[0], t[1]), mid_node(t[1], t[2]),
                          mid_node(t[2], t[0]), mid_node(t[0], t[3]), mid_node(t[1], t[3]),
                          mid_node(t[2], t[3])});
  }
  return q;
}

// A node set held at one displacement (all three components), unit m.
struct C3d10Press {
  std::vector<int> nodes;
  Eigen::Vector3d displacement_m{Eigen::Vector3d::Zero()};
};

// Writes the C3D10 deck, runs ccx (one thread, at most 120 s), returns every node's
// displacement and the reactions of the fixed and pressed nodes (CalculixResult). A failure of
// ccx is a test failure (empty result).
inline CalculixResult solve_c3d10(const std::string& tag, const QuadraticMesh& q,
                                  const Material& mat, const std::vector<int>& fixed,
                                  const Eigen::VectorXd& loads, const C3d10Press& press = {}) {
  const auto dir = neurosim::testing::temp_dir(tag);
  auto node_set = [](std::ofstream& out, const char* name, const std::vector<int>& nodes) {
    out << "*NSET, NSET=" << name << "\n";
    for (std::size_t i = 0; i < nodes.size(); ++i)
      out << nodes[i] + 1 << (i + 1 == nodes.size() || i % 10 == 9 ? "\n" : ", ");
  };
  {
    std::ofstream out(dir / "job.inp");
    out.precision(13);  // ccx reads at most 20 characters per number
    out << "** neurosim element test: " << tag << "\n*NODE, NSET=NALL\n";
    for (std::size_t v = 0; v < q.nodes.size(); ++v)
      out << v + 1 << ", " << q.nodes[v].x() << ", " << q.nodes[v].y() << ", " << q.nodes[v].z()
          << "\n";
    out << "*ELEMENT, TYPE=C3D10, ELSET=EALL\n";
    for (std::size_t e = 0; e < q.elements.size(); ++e) {
      out << e + 1;
      for (int n : q.elements[e]) out << ", " << n + 1;
      out << "\n";
    }
    out << "*MATERIAL, NAME=M\n*ELASTIC\n"
        << mat.youngs_modulus_pa << ", " << mat.poisson_ratio
        << "\n*SOLID SECTION, ELSET=EALL, MATERIAL=M\n";
    node_set(out, "NFIX", fixed);
    std::vector<int> rf = fixed;
    if (!press.nodes.empty()) {
      node_set(out, "NPRESS", press.nodes);
      rf.insert(rf.end(), press.nodes.begin(), press.nodes.end());
    }
    node_set(out, "NRF", rf);
    out << "*STEP\n*STATIC\n*BOUNDARY\nNFIX, 1, 3\n";
    for (int a = 0; a < 3 && !press.nodes.empty(); ++a)
      out << "NPRESS, " << a + 1 << ", " << a + 1 << ", " << press.displacement_m[a] << "\n";
    bool any_load = false;
    for (Eigen::Index d = 0; d < loads.size(); ++d) {
      if (loads[d] == 0.0) continue;
      if (!any_load) out << "*CLOAD\n";
      any_load = true;
      out << d / 3 + 1 << ", " << d % 3 + 1 << ", " << loads[d] << "\n";
    }
    out << "*NODE PRINT, NSET=NALL\nU\n*NODE PRINT, NSET=NRF, TOTALS=NO\nRF\n*END STEP\n";
  }
  const std::string cmd = "cd '" + dir.string() +
                          "' && OMP_NUM_THREADS=1 CCX_NPROC_EQUATION_SOLVER=1 timeout -k 5 120 "
                          "ccx -i job > job.log 2>&1";
  const int status = std::system(cmd.c_str());
  const int code = (status != -1 && WIFEXITED(status)) ? WEXITSTATUS(status) : -1;
  const std::string log = neurosim::testing::slurp(dir / "job.log");
  if (code != 0 || log.find("*ERROR") != std::string::npos) {
    ADD_FAILURE() << "ccx failed (exit " << code << ", Debian package calculix-ccx):\n" << log;
    return {};
  }
  CalculixResult r = read_calculix_dat(dir / "job.dat", q.nodes.size());
  std::filesystem::remove_all(dir);
  return r;
}

}  // namespace neurosim::fem::testing
