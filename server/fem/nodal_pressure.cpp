#include "server/fem/nodal_pressure.hpp"

#include "server/fem/tet_element.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

void NodalPressure::adjacency(const mesh::TetMesh& mesh, int distance, std::vector<int>& offset,
                              std::vector<int>& nodes) {
  const int n = static_cast<int>(mesh.num_vertices());
  std::vector<int> count(n + 1, 0);
  for (const auto& t : mesh.tets())
    for (int a = 0; a < 4; ++a) count[t[a] + 1] += 4;
  for (int v = 0; v < n; ++v) count[v + 1] += count[v];
  std::vector<int> adj(count[n]);
  std::vector<int> fill(count.begin(), count.end() - 1);
  for (const auto& t : mesh.tets())
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) adj[fill[t[a]]++] = t[b];
  offset.assign(n + 1, 0);
  nodes.clear();
  nodes.reserve(adj.size() / 3);
  for (int v = 0; v < n; ++v) {
    auto first = adj.begin() + count[v], last = adj.begin() + count[v + 1];
    std::sort(first, last);
    last = std::unique(first, last);
    nodes.insert(nodes.end(), first, last);
    offset[v + 1] = static_cast<int>(nodes.size());
  }
  if (distance <= 1) return;
  // Square of the 1-ring: every node of every neighbour's 1-ring, marked once per node.
  std::vector<int> offset2(n + 1, 0), nodes2, mark(n, -1), ring;
  nodes2.reserve(nodes.size() * 4);
  for (int v = 0; v < n; ++v) {
    ring.clear();
    for (int k = offset[v]; k < offset[v + 1]; ++k) {
      const int u = nodes[k];
      for (int l = offset[u]; l < offset[u + 1]; ++l) {
        const int w = nodes[l];
        if (mark[w] != v) {
          mark[w] = v;
          ring.push_back(w);
        }
      }
    }
    std::sort(ring.begin(), ring.end());
    nodes2.insert(nodes2.end(), ring.begin(), ring.end());
    offset2[v + 1] = static_cast<int>(nodes2.size());
  }
  offset.swap(offset2);
  nodes.swap(nodes2);
}

NodalPressure::NodalPressure(const mesh::TetMesh& mesh, const MaterialMap& materials)
    : tets_(mesh.tets()) {
  materials.validate(mesh.num_tets());
  const std::size_t n = mesh.num_vertices();
  const auto& x = mesh.vertices();
  element_volume_m3_.resize(tets_.size());
  element_bulk_pa_.resize(tets_.size());
  nodal_volume_m3_.assign(n, 0.0);
  nodal_bulk_pa_.assign(n, 0.0);
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const auto& t = tets_[e];
    const TetGeometry g = tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e));
    const Material& m = materials.of_tet(e);
    element_volume_m3_[e] = g.volume_m3;
    // K = lambda + 2 mu / 3 = E / (3 (1 - 2 nu)) = 2 / D1 (neo-Hooke), unit Pa.
    element_bulk_pa_[e] = m.lame_lambda_pa() + 2.0 / 3.0 * m.shear_modulus_pa();
    for (int a = 0; a < 4; ++a) {
      nodal_volume_m3_[t[a]] += 0.25 * g.volume_m3;
      nodal_bulk_pa_[t[a]] += 0.25 * g.volume_m3 * element_bulk_pa_[e];
    }
  }
  // A node in no tetrahedron (carved meshes keep them) has no volume and no volumetric term.
  for (std::size_t v = 0; v < n; ++v)
    if (nodal_volume_m3_[v] > 0.0) nodal_bulk_pa_[v] /= nodal_volume_m3_[v];
  // Node -> tetrahedra.
  node_tet_offset_.assign(n + 1, 0);
  for (const auto& t : tets_)
    for (int a = 0; a < 4; ++a) ++node_tet_offset_[t[a] + 1];
  for (std::size_t v = 0; v < n; ++v) node_tet_offset_[v + 1] += node_tet_offset_[v];
  node_tet_.resize(node_tet_offset_[n]);
  std::vector<int> fill(node_tet_offset_.begin(), node_tet_offset_.end() - 1);
  for (std::size_t e = 0; e < tets_.size(); ++e)
    for (int a = 0; a < 4; ++a) node_tet_[fill[tets_[e][a]]++] = static_cast<int>(e);
  adjacency(mesh, 1, patch_offset_, patch_);
  incidence_patch_.resize(node_tet_.size());
  for (std::size_t v = 0; v < n; ++v) {
    const int* first = patch_.data() + patch_offset_[v];
    const int* last = patch_.data() + patch_offset_[v + 1];
    for (int i = node_tet_offset_[v]; i < node_tet_offset_[v + 1]; ++i) {
      const auto& t = tets_[node_tet_[i]];
      for (int b = 0; b < 4; ++b)
        incidence_patch_[i][b] = static_cast<int>(std::lower_bound(first, last, t[b]) - first);
    }
  }
}

void NodalPressure::nodal_strain(const std::vector<double>& element_theta,
                                 std::vector<double>& nodal_theta) const {
  nodal_theta.assign(nodal_volume_m3_.size(), 0.0);
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    const double share = 0.25 * element_volume_m3_[e] * element_theta[e];
    for (int a = 0; a < 4; ++a) nodal_theta[tets_[e][a]] += share;
  }
  for (std::size_t v = 0; v < nodal_theta.size(); ++v)
    if (nodal_volume_m3_[v] > 0.0) nodal_theta[v] /= nodal_volume_m3_[v];
}

void NodalPressure::element_pressure(const std::vector<double>& nodal_theta,
                                     std::vector<double>& element_pressure_pa) const {
  element_pressure_pa.resize(tets_.size());
  for (std::size_t e = 0; e < tets_.size(); ++e) {
    double p = 0.0;
    for (int a = 0; a < 4; ++a) p += nodal_bulk_pa_[tets_[e][a]] * nodal_theta[tets_[e][a]];
    element_pressure_pa[e] = 0.25 * p;
  }
}

double NodalPressure::energy(const std::vector<double>& nodal_theta) const {
  double e = 0.0;
  for (std::size_t v = 0; v < nodal_theta.size(); ++v)
    e += 0.5 * nodal_volume_m3_[v] * nodal_bulk_pa_[v] * nodal_theta[v] * nodal_theta[v];
  return e;
}

void NodalPressure::add_nodal_stiffness(const std::vector<Eigen::Matrix<double, 4, 3>>& w,
                                        SparseMatrix& k, std::vector<double>& q) const {
  const int* outer = k.outerIndexPtr();
  const int* inner = k.innerIndexPtr();
  double* values = k.valuePtr();
  for (std::size_t a = 0; a < nodal_volume_m3_.size(); ++a) {
    if (!(nodal_volume_m3_[a] > 0.0)) continue;  // in no tetrahedron
    const int p0 = patch_offset_[a], m = patch_offset_[a + 1] - p0;
    q.assign(3 * static_cast<std::size_t>(m), 0.0);
    // q_a = d thetabar_a / du over the 1-ring of a.
    for (int i = node_tet_offset_[a]; i < node_tet_offset_[a + 1]; ++i) {
      const int e = node_tet_[i];
      const double weight = 0.25 * element_volume_m3_[e] / nodal_volume_m3_[a];
      for (int b = 0; b < 4; ++b) {
        const int idx = incidence_patch_[i][b];
        for (int d = 0; d < 3; ++d) q[3 * idx + d] += weight * w[e](b, d);
      }
    }
    const double s = nodal_volume_m3_[a] * nodal_bulk_pa_[a];
    // Column node c, row node b, both in the 1-ring (sorted): merge along column 3c's rows.
    for (int jc = 0; jc < m; ++jc) {
      const int c = patch_[p0 + jc];
      const int col0 = outer[3 * c], rows = outer[3 * c + 1] - col0;
      int r = 0;
      for (int ib = 0; ib < m; ++ib) {
        const int b = patch_[p0 + ib];
        while (r < rows && inner[col0 + r] != 3 * b) r += 3;
        if (r >= rows) {
          throw std::logic_error("anp-tet: stiffness pattern lacks a nodal-pressure block");
        }
        for (int j = 0; j < 3; ++j) {
          const double qc = s * q[3 * jc + j];
          double* dst = values + outer[3 * c + j] + r;
          for (int i = 0; i < 3; ++i) dst[i] += q[3 * ib + i] * qc;
        }
      }
    }
  }
}

}  // namespace neurosim::fem
