// The external reference of the element tests: CalculiX's quadratic tetrahedra (C3D10) on a
// linear-tetrahedron mesh with a node added at the middle of every edge, linear elastic, under
// nodal loads and/or a node set held at a prescribed displacement (ccx run in a temporary
// directory, one thread, bounded in time). Used by locking_test (a block, a cantilever) and
// brain_press_test (a coarse Colin27 brain).
#pragma once

#include "bench/c3d10_press.hpp"
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

// The mesh with a node at the middle of every edge, C3D10 connectivity in CalculiX's order
// (bench/c3d10_press.hpp, the benches' outside reference too).
using QuadraticMesh = neurosim::bench::QuadraticTets;
inline QuadraticMesh quadratic(const mesh::TetMesh& m) { return neurosim::bench::quadratic_tets(m); }

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

  {
    std::ofstream out(dir / "job.inp");
    out.precision(13);  // ccx reads at most 20 characters per number
    out << "** neurosim element test: " << tag << "\n";
    neurosim::bench::write_c3d10_mesh(out, q);
    out << "*MATERIAL, NAME=M\n*ELASTIC\n"
        << mat.youngs_modulus_pa << ", " << mat.poisson_ratio
        << "\n*SOLID SECTION, ELSET=EALL, MATERIAL=M\n";
    neurosim::bench::write_node_set(out, "NFIX", fixed);
    std::vector<int> rf = fixed;
    if (!press.nodes.empty()) {
      neurosim::bench::write_node_set(out, "NPRESS", press.nodes);
      rf.insert(rf.end(), press.nodes.begin(), press.nodes.end());
    }
    neurosim::bench::write_node_set(out, "NRF", rf);
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
