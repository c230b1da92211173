#include "server/fem/smoothed_strain.hpp"

#include "server/fem/tet_element.hpp"

#include <algorithm>
#include <array>
#include <map>
#include <stdexcept>
#include <string>
#include <tuple>

namespace neurosim::fem {

SmoothedStrain::SmoothedStrain(const mesh::TetMesh& mesh, const MaterialMap& materials,
                               const SparseMatrix& pattern) {
  materials.validate(mesh.num_tets());
  const auto& tets = mesh.tets();
  const auto& x = mesh.vertices();
  std::vector<TetGeometry> geometry;
  geometry.reserve(tets.size());
  for (std::size_t e = 0; e < tets.size(); ++e) {
    const auto& t = tets[e];
    geometry.push_back(tet_geometry({x[t[0]], x[t[1]], x[t[2]], x[t[3]]}, static_cast<int>(e)));
  }
  // Cells keyed (node, node or -1, material): edge cells get V_e / 6 of each tetrahedron on the
  // edge, node cells V_e / 4 of each tetrahedron on the node.
  struct Share {
    int cell;
    int tet;
    double fraction;  // of the tetrahedron's volume
  };
  std::map<std::tuple<int, int, int>, int> cell_of;
  std::vector<Share> shares;
  shares.reserve(tets.size() * 10);
  std::vector<double> geometric_m3;
  std::vector<char> is_edge;
  auto cell = [&](int a, int b, int m) {
    const auto key = std::make_tuple(std::min(a, b), std::max(a, b), m);
    const auto [it, inserted] = cell_of.emplace(key, static_cast<int>(geometric_m3.size()));
    if (inserted) {
      geometric_m3.push_back(0.0);
      material_.push_back(m);
      is_edge.push_back(b >= 0 ? 1 : 0);
    }
    return it->second;
  };
  for (std::size_t e = 0; e < tets.size(); ++e) {
    const auto& t = tets[e];
    const int m = materials.tet_material.empty() ? 0 : materials.tet_material[e];
    const int te = static_cast<int>(e);
    for (int a = 0; a < 4; ++a) {
      for (int b = a + 1; b < 4; ++b) shares.push_back({cell(t[a], t[b], m), te, 1.0 / 6.0});
      shares.push_back({cell(t[a], -1, m), te, 0.25});
    }
  }
  for (const Share& s : shares) geometric_m3[s.cell] += s.fraction * geometry[s.tet].volume_m3;
  std::stable_sort(shares.begin(), shares.end(),
                   [](const Share& l, const Share& r) { return l.cell < r.cell; });
  const int num_cells = static_cast<int>(geometric_m3.size());
  volume_m3_.resize(num_cells);
  node_offset_.assign(num_cells + 1, 0);
  std::size_t first = 0;
  std::vector<int> cell_nodes;
  for (int c = 0; c < num_cells; ++c) {
    std::size_t last = first;
    while (last < shares.size() && shares[last].cell == c) ++last;
    volume_m3_[c] = (is_edge[c] ? 1.0 - kNodeShare : kNodeShare) * geometric_m3[c];
    // The cell's nodes: every node of its tetrahedra.
    cell_nodes.clear();
    for (std::size_t s = first; s < last; ++s)
      for (int a = 0; a < 4; ++a) cell_nodes.push_back(tets[shares[s].tet][a]);
    std::sort(cell_nodes.begin(), cell_nodes.end());
    cell_nodes.erase(std::unique(cell_nodes.begin(), cell_nodes.end()), cell_nodes.end());
    const std::size_t base = nodes_.size();
    nodes_.insert(nodes_.end(), cell_nodes.begin(), cell_nodes.end());
    gradient_.resize(nodes_.size(), Eigen::Vector3d::Zero());
    // g_cb = sum_e (V_e^c / V_c) grad N_b^e.
    for (std::size_t s = first; s < last; ++s) {
      const auto& t = tets[shares[s].tet];
      const TetGeometry& g = geometry[shares[s].tet];
      const double w = shares[s].fraction * g.volume_m3 / geometric_m3[c];
      for (int a = 0; a < 4; ++a) {
        const auto at = std::lower_bound(cell_nodes.begin(), cell_nodes.end(), t[a]);
        gradient_[base + (at - cell_nodes.begin())] += w * g.gradients.row(a).transpose();
      }
    }
    node_offset_[c + 1] = static_cast<int>(nodes_.size());
    max_cell_nodes_ = std::max(max_cell_nodes_, static_cast<int>(cell_nodes.size()));
    first = last;
  }
  // Positions of the cells' node blocks in the pattern.
  const int* outer = pattern.outerIndexPtr();
  const int* inner = pattern.innerIndexPtr();
  pair_offset_.assign(num_cells + 1, 0);
  for (int c = 0; c < num_cells; ++c) {
    const int n = node_offset_[c + 1] - node_offset_[c];
    pair_offset_[c + 1] = pair_offset_[c] + n * n;
  }
  pair_row_.resize(pair_offset_[num_cells]);
  for (int c = 0; c < num_cells; ++c) {
    const int n0 = node_offset_[c], n = node_offset_[c + 1] - n0;
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        const int row = 3 * nodes_[n0 + i], col = 3 * nodes_[n0 + j];
        const int* begin = inner + outer[col];
        const int* end = inner + outer[col + 1];
        const int* at = std::lower_bound(begin, end, row);
        if (at == end || *at != row) {
          throw std::logic_error("smoothed-tet: stiffness pattern lacks a smoothing cell's block");
        }
        pair_row_[pair_offset_[c] + i * n + j] = static_cast<int>(at - begin);
      }
    }
  }
}

Eigen::Matrix3d SmoothedStrain::displacement_gradient(int cell, const Eigen::VectorXd& u_m) const {
  Eigen::Matrix3d h = Eigen::Matrix3d::Zero();
  for (int k = node_offset_[cell]; k < node_offset_[cell + 1]; ++k)
    h.noalias() += u_m.segment<3>(3 * nodes_[k]) * gradient_[k].transpose();
  return h;
}

void SmoothedStrain::add_force(int cell, const Eigen::Matrix3d& p_pa, Eigen::VectorXd& f_n) const {
  const double v = volume_m3_[cell];
  for (int k = node_offset_[cell]; k < node_offset_[cell + 1]; ++k)
    f_n.segment<3>(3 * nodes_[k]).noalias() += v * (p_pa * gradient_[k]);
}

void SmoothedStrain::add_tangent(int cell, const StressTangent& dp_df,
                                 std::vector<Eigen::Matrix<double, 9, 3>>& scratch,
                                 SparseMatrix& k) const {
  const int n0 = node_offset_[cell], n = node_offset_[cell + 1] - n0;
  const double v = volume_m3_[cell];
  // vec(dF) = sum_b (du_b g_b^T) at vec index i + 3 l: T_c(:, j) = sum_m dP/dF(:, j + 3 m) g_cm.
  for (int c = 0; c < n; ++c) {
    const Eigen::Vector3d& g = gradient_[n0 + c];
    for (int j = 0; j < 3; ++j)
      scratch[c].col(j) = v * (dp_df.col(j) * g(0) + dp_df.col(j + 3) * g(1) + dp_df.col(j + 6) * g(2));
  }
  const int* outer = k.outerIndexPtr();
  double* values = k.valuePtr();
  const int* rows = pair_row_.data() + pair_offset_[cell];
  for (int j_node = 0; j_node < n; ++j_node) {
    const int col = 3 * nodes_[n0 + j_node];
    const Eigen::Matrix<double, 9, 3>& t = scratch[j_node];
    for (int i_node = 0; i_node < n; ++i_node) {
      const Eigen::Vector3d& g = gradient_[n0 + i_node];
      // K_bc(i, j) = sum_l g_b,l T_c(i + 3 l, j).
      const Eigen::Matrix3d block =
          g(0) * t.topRows<3>() + g(1) * t.middleRows<3>(3) + g(2) * t.bottomRows<3>();
      const int r = rows[i_node * n + j_node];
      for (int j = 0; j < 3; ++j) {
        double* dst = values + outer[col + j] + r;
        for (int i = 0; i < 3; ++i) dst[i] += block(i, j);
      }
    }
  }
}

}  // namespace neurosim::fem
