// External reference export: the same problem written as a CalculiX (ccx) input deck, ccx run
// in a directory, and its .dat output (nodal U and RF) read back. Used by verification tests.
#pragma once

#include "server/fem/material.hpp"
#include "server/fem/prescribed.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>

#include <filesystem>
#include <string>
#include <vector>

namespace neurosim::fem {

// The analysis of the step. Default: linear elastic, small strain (*ELASTIC, *STATIC). The
// nonlinear tier's reference: *HYPERELASTIC, NEO HOOKE with C10 = E / (4 (1 + nu)) and
// D1 = 6 (1 - 2 nu) / E per material, in a *STEP, NLGEOM with `increments` equal initial
// increments (ccx may cut them back) and tight *CONTROLS so that ccx's answer is converged
// well below the comparison tolerance.
struct CalculixStep {
  bool neo_hookean_nlgeom{false};
  int increments{10};
};

// Boundary conditions and loads of one static step.
struct CalculixLoads {
  std::vector<int> fixed_nodes;                // u = 0 in x, y, z
  std::vector<int> prescribed_nodes;           // u given in x, y, z
  Eigen::VectorXd prescribed_displacements_m;  // 3 per prescribed node, node-major, unit m
  // Prescribed by component (only the marked components held, the others free); validated
  // as StaticSolver::solve_prescribed_dofs does (expand_prescribed against fixed_nodes), and
  // no node may also be in prescribed_nodes.
  std::vector<PrescribedDofs> prescribed_sets;
  Eigen::VectorXd forces_n;  // empty or 3N nodal forces, unit N (dead loads in NLGEOM)
  CalculixStep step;
};

// Writes a C3D4 deck: *NODE (id = node + 1), *ELEMENT per material (ELSET Ek, id = tet + 1),
// *MATERIAL Mk / *ELASTIC and *SOLID SECTION per used material, then one *STATIC step with
// *BOUNDARY, *CLOAD, *NODE PRINT U (all nodes) and RF (fixed + prescribed nodes, set NRF).
// prescribed_sets[k] becomes node set NPk and one *BOUNDARY line "NPk, a, a, value" per
// prescribed component a (1 = x, 2 = y, 3 = z); ccx leaves the other components free.
// Numbers are written with 17 significant digits. Throws on non-finite or out-of-range input,
// and (std::invalid_argument, naming the material and the element) for materials whose element
// is not linear-tet: C3D4 is linear-tet's element, and no deck is written for anp-tet or
// smoothed-tet (their external reference is C3D10 on the same mesh: tests/server/fem).
void write_calculix_input(const std::filesystem::path& inp_file, const mesh::TetMesh& mesh,
                          const MaterialMap& materials, const CalculixLoads& loads);

struct CalculixResult {
  Eigen::VectorXd displacement_m;  // 3N, unit m
  // 3N, unit N; zero where ccx printed none. ccx's RF is (K u) at the node: a load applied on a
  // constrained dof is not subtracted, so compare with StaticSolver's reaction_n + forces_n.
  Eigen::VectorXd reaction_n;
  std::vector<char> has_reaction;  // per node: ccx printed RF for it
  // Step time of the last printed block (ccx prints every increment; the last one is kept):
  // 1 when the step completed.
  double time{0.0};
};

// Reads the displacements and the reaction forces printed by *NODE PRINT into a .dat file (the
// last increment's when there are several).
// Throws std::runtime_error naming the file and line on a malformed or incomplete file.
CalculixResult read_calculix_dat(const std::filesystem::path& dat_file, std::size_t num_nodes);

struct CalculixRunOptions {
  std::string executable{"ccx"};
  double timeout_s{300.0};  // wall clock, unit s; ccx is killed after it
};

// Writes <work_dir>/<job>.inp, runs `ccx -i <job>` with cwd work_dir (bounded by timeout_s,
// one thread), reads <job>.dat. Refuses what write_calculix_input refuses (before running ccx).
// Throws std::runtime_error with the tail of ccx's log on failure,
// including an NLGEOM step that stopped before its end (time < 1).
CalculixResult run_calculix(const std::filesystem::path& work_dir, const std::string& job,
                            const mesh::TetMesh& mesh, const MaterialMap& materials,
                            const CalculixLoads& loads, const CalculixRunOptions& options = {});

}  // namespace neurosim::fem
