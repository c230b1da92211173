#include "server/fem/assembly.hpp"

#include "server/fem/elastic_forces.hpp"
#include "server/fem/nodal_pressure.hpp"
#include "server/fem/tet_element.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

StiffnessAssembler::StiffnessAssembler(const mesh::TetMesh& mesh, Element element)
    : element_(element), num_nodes_(mesh.num_vertices()), num_tets_(mesh.num_tets()) {
  const auto& tets = mesh.tets();
  const int n = static_cast<int>(num_nodes_);
  // Node-node adjacency (including the node itself), CSR, sorted per node; anp-tet's nodal
  // volumetric terms couple the neighbours of a node's neighbours.
  std::vector<int> nbr_offset, nbr;
  // smoothed-tet's node cells couple the same pairs.
  NodalPressure::adjacency(mesh, element == Element::kLinearTet ? 1 : 2, nbr_offset, nbr);
  // Column 3b+j holds rows 3a+i for every neighbour a of b (sorted), i = 0..2.
  const long long nnz = 9LL * static_cast<long long>(nbr.size());
  if (nnz > std::numeric_limits<int>::max()) {
    throw std::invalid_argument("StiffnessAssembler: mesh too large for 32-bit sparse indices");
  }
  pattern_.resize(3 * n, 3 * n);
  pattern_.resizeNonZeros(static_cast<Eigen::Index>(nnz));
  int* outer = pattern_.outerIndexPtr();
  int* inner = pattern_.innerIndexPtr();
  int pos = 0;
  for (int b = 0; b < n; ++b) {
    for (int j = 0; j < 3; ++j) {
      outer[3 * b + j] = pos;
      for (int k = nbr_offset[b]; k < nbr_offset[b + 1]; ++k) {
        for (int i = 0; i < 3; ++i) {
          inner[pos++] = 3 * nbr[k] + i;
        }
      }
    }
  }
  outer[3 * n] = pos;
  std::fill_n(pattern_.valuePtr(), nnz, 0.0);

  // Position of each element block in the value array.
  block_start_.resize(num_tets_ * 48);
  for (std::size_t e = 0; e < num_tets_; ++e) {
    const auto& t = tets[e];
    for (int a = 0; a < 4; ++a) {
      for (int b = 0; b < 4; ++b) {
        const int* first = nbr.data() + nbr_offset[t[b]];
        const int* last = nbr.data() + nbr_offset[t[b] + 1];
        const int k = static_cast<int>(std::lower_bound(first, last, t[a]) - first);
        const int deg = nbr_offset[t[b] + 1] - nbr_offset[t[b]];
        for (int j = 0; j < 3; ++j) {
          block_start_[e * 48 + (4 * a + b) * 3 + j] = 9 * nbr_offset[t[b]] + j * 3 * deg + 3 * k;
        }
      }
    }
  }
}

void StiffnessAssembler::assemble(const mesh::TetMesh& mesh, const MaterialMap& materials,
                                  SparseMatrix& k) const {
  if (mesh.num_vertices() != num_nodes_ || mesh.num_tets() != num_tets_) {
    throw std::invalid_argument(
        "StiffnessAssembler: mesh '" + mesh.source() + "' (" + std::to_string(mesh.num_vertices()) +
        " nodes, " + std::to_string(mesh.num_tets()) + " tets) is not the mesh of this pattern");
  }
  materials.validate(num_tets_);
  if (materials.element() != element_) {
    throw std::invalid_argument(std::string("StiffnessAssembler: the materials ask for element '") +
                                element_name(materials.element()) + "', the pattern is for '" +
                                element_name(element_) + "'");
  }
  if (element_ == Element::kSmoothedTet) {
    // The smoothing cells' stiffness is the LINEAR tier's tangent (at any u: it is constant).
    ElasticForces(mesh, materials, Tier::kLinear)
        .tangent(Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(num_nodes_)), false, k);
    return;
  }
  const bool anp = element_ == Element::kAnpTet;
  std::vector<double> lambda(materials.materials.size()), mu(materials.materials.size());
  for (std::size_t m = 0; m < materials.materials.size(); ++m) {
    lambda[m] = materials.materials[m].lame_lambda_pa();
    mu[m] = materials.materials[m].shear_modulus_pa();
    // anp-tet: the element keeps the deviatoric part (lambda - K = -2 mu / 3), the nodes the
    // volumetric one (nodal_pressure.hpp).
    if (anp) lambda[m] = -2.0 / 3.0 * mu[m];
  }
  std::vector<Eigen::Matrix<double, 4, 3>> gradients(anp ? num_tets_ : 0);
  if (k.rows() != pattern_.rows() || k.nonZeros() != pattern_.nonZeros() || !k.isCompressed()) {
    k = pattern_;
  }
  double* values = k.valuePtr();
  std::fill_n(values, k.nonZeros(), 0.0);
  const auto& tets = mesh.tets();
  const auto& x = mesh.vertices();
  double grad[4][3], kab[3][3];
  for (std::size_t e = 0; e < num_tets_; ++e) {
    const auto& t = tets[e];
    const TetGeometry g = tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e));
    const int m = materials.tet_material.empty() ? 0 : materials.tet_material[e];
    for (int a = 0; a < 4; ++a) {
      for (int i = 0; i < 3; ++i) {
        grad[a][i] = g.gradients(a, i);
      }
    }
    if (anp) gradients[e] = g.gradients;
    const double vl = g.volume_m3 * lambda[m], vm = g.volume_m3 * mu[m];
    const int* start = block_start_.data() + e * 48;
    // Blocks (a, b), b >= a, scattered to (a, b) and transposed to (b, a): K_e is never formed.
    for (int a = 0; a < 4; ++a) {
      for (int b = a; b < 4; ++b) {
        tet_stiffness_block(grad[a], grad[b], vl, vm, kab);
        for (int j = 0; j < 3; ++j) {
          double* dst = values + start[(4 * a + b) * 3 + j];
          for (int i = 0; i < 3; ++i) {
            dst[i] += kab[i][j];
          }
        }
        if (b == a) {
          continue;
        }
        for (int j = 0; j < 3; ++j) {
          double* dst = values + start[(4 * b + a) * 3 + j];
          for (int i = 0; i < 3; ++i) {
            dst[i] += kab[j][i];
          }
        }
      }
    }
  }
  // LINEAR volumetric strain tr(grad u): d theta_e / d u_b = grad N_b.
  std::vector<double> q;
  if (anp) NodalPressure(mesh, materials).add_nodal_stiffness(gradients, k, q);
}

SparseMatrix assemble_stiffness(const mesh::TetMesh& mesh, const MaterialMap& materials) {
  SparseMatrix k;
  StiffnessAssembler(mesh, materials.element()).assemble(mesh, materials, k);
  return k;
}

}  // namespace neurosim::fem
