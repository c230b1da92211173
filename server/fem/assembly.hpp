// Global stiffness assembly: K (3N x 3N, dof = 3*node + axis, unit N/m) from a TetMesh.
#pragma once

#include "server/fem/material.hpp"
#include "server/mesh/tet_mesh.hpp"

#include <Eigen/Core>
#include <Eigen/SparseCore>

#include <vector>

namespace neurosim::fem {

using SparseMatrix = Eigen::SparseMatrix<double>;  // column-major, int indices

// Builds the sparsity pattern of K once (Model) and then fills values in place: every 3x3
// node block of every tetrahedron has a precomputed position in K's value array, so assembly
// is element kernels plus scatter-adds, with no sorting and no allocation after the first fill.
class StiffnessAssembler {
 public:
  // The pattern of `element`: node neighbours (linear-tet) or neighbours of neighbours (anp-tet,
  // smoothed-tet).
  explicit StiffnessAssembler(const mesh::TetMesh& mesh, Element element = Element::kLinearTet);

  // K with both triangles stored (symmetric). `k` gets the pattern on the first call and is
  // refilled in place afterwards. Throws std::invalid_argument for an invalid material map or
  // an inverted / degenerate / non-finite tetrahedron (naming it), a mesh of another size, or
  // materials naming another element than the pattern's.
  void assemble(const mesh::TetMesh& mesh, const MaterialMap& materials, SparseMatrix& k) const;

  // Adds an element matrix (dof 3 a + i, a local node of tetrahedron `tet`) into the value
  // array of a matrix with this pattern (nonlinear tangents, assembled element by element).
  void add_element(std::size_t tet, const Eigen::Matrix<double, 12, 12>& k_e, double* values) const {
    const int* start = block_start_.data() + tet * 48;
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        for (int j = 0; j < 3; ++j) {
          double* dst = values + start[(4 * a + b) * 3 + j];
          for (int i = 0; i < 3; ++i) {
            dst[i] += k_e(3 * a + i, 3 * b + j);
          }
        }
      }
    }
  }

  // Pattern of K (values zero): (3N x 3N).
  const SparseMatrix& pattern() const { return pattern_; }
  std::size_t num_nodes() const { return num_nodes_; }
  std::size_t num_tets() const { return num_tets_; }
  Element element() const { return element_; }

 private:
  Element element_{Element::kLinearTet};
  std::size_t num_nodes_{0};
  std::size_t num_tets_{0};
  SparseMatrix pattern_;
  // Per tetrahedron, per local node pair (a, b), per axis j: index in the value array of
  // entry (3 tet[a], 3 tet[b] + j); rows 3 tet[a] + 1, + 2 follow it.
  std::vector<int> block_start_;
};

// Convenience: one-shot assembly (builds a StiffnessAssembler for the materials' element).
SparseMatrix assemble_stiffness(const mesh::TetMesh& mesh, const MaterialMap& materials);

}  // namespace neurosim::fem
