// TieCondensation: one embedded mesh condensed onto its tied nodes (see the header).
#include "server/interaction/tie_condensation.hpp"

#include "server/fem/assembly.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace neurosim::interaction {

TieCondensation::TieCondensation(const TieDefinition& def, int host_vertices) {
  if (def.embedded == nullptr) throw std::invalid_argument("TieCondensation: no mesh");
  const mesh::TetMesh& embedded = *def.embedded;
  if (def.tri_nodes.size() != def.surface_nodes.size() ||
      def.weights.size() != def.surface_nodes.size()) {
    throw std::invalid_argument("TieCondensation: coupling map sizes differ");
  }
  mesh_ = def.mesh;
  geometry_ = &embedded;
  material_ = def.material;
  fixed_nodes_ = def.fixed_nodes;
  std::sort(fixed_nodes_.begin(), fixed_nodes_.end());
  max_map_distance_m_ = def.max_map_distance_m;
  const int nb = static_cast<int>(embedded.num_vertices());
  for (std::size_t k = 0; k < def.surface_nodes.size(); ++k) {
    const int v = def.surface_nodes[k];
    if (v < 0 || v >= nb) {
      throw std::invalid_argument("TieCondensation: embedded node " + std::to_string(v) +
                                  " out of range");
    }
    // A fixed node of B stays fixed: tying it too would over-constrain A.
    if (std::binary_search(fixed_nodes_.begin(), fixed_nodes_.end(), v)) continue;
    double sum = 0.0;
    for (int a = 0; a < 3; ++a) {
      const int h = def.tri_nodes[k][a];
      if (h < 0 || h >= host_vertices || !std::isfinite(def.weights[k][a])) {
        throw std::invalid_argument("TieCondensation: bad coupling map entry for embedded node " +
                                    std::to_string(v));
      }
      sum += def.weights[k][a];
    }
    if (std::abs(sum - 1.0) > 1e-9) {
      throw std::invalid_argument("TieCondensation: weights of embedded node " + std::to_string(v) +
                                  " sum to " + std::to_string(sum));
    }
    tied_nodes_.push_back(v);
    weights_.push_back(def.weights[k]);
    host_nodes_.push_back(def.tri_nodes[k]);
  }
  if (tied_nodes_.empty())
    throw std::invalid_argument("TieCondensation: no node of the embedded mesh to tie");

  // Condensation of B onto its tied dofs: S_B = K_ss - K_si K_ii^-1 K_is.
  std::vector<int> constrained = fixed_nodes_;
  constrained.insert(constrained.end(), tied_nodes_.begin(), tied_nodes_.end());
  std::sort(constrained.begin(), constrained.end());
  const auto materials = fem::MaterialMap::uniform(material_);
  fem::SparseMatrix k_b;
  const int t = static_cast<int>(tied_nodes_.size());
  std::vector<int> tied_dof_index(3 * nb, -1);
  for (int k = 0; k < t; ++k)
    for (int a = 0; a < 3; ++a) tied_dof_index[3 * tied_nodes_[k] + a] = 3 * k + a;
  if (static_cast<int>(constrained.size()) < nb) {
    fem::SolverOptions opts;
    opts.check_rigid_modes = false;  // the whole surface is fixed: no rigid mode is left
    interior_ = std::make_unique<fem::StaticSolver>(embedded, materials, constrained, opts);
    k_b = interior_->stiffness();
  } else {
    k_b = fem::assemble_stiffness(embedded, materials);
  }
  // Blocks of K_B kept sparse: K_ss (tied x tied) and K_is (interior free x tied).
  std::vector<Eigen::Triplet<double>> ss, is;
  const int nf = interior_ ? interior_->num_free_dofs() : 0;
  for (int c = 0; c < k_b.outerSize(); ++c) {
    const int tc = tied_dof_index[c];
    if (tc < 0) continue;
    for (fem::SparseMatrix::InnerIterator it(k_b, c); it; ++it) {
      const int r = static_cast<int>(it.row());
      if (tied_dof_index[r] >= 0) {
        ss.emplace_back(tied_dof_index[r], tc, it.value());
      } else if (nf > 0 && interior_->reduced_index()[r] >= 0) {
        is.emplace_back(interior_->reduced_index()[r], tc, it.value());
      }
    }
  }
  k_ss_.resize(3 * t, 3 * t);
  k_ss_.setFromTriplets(ss.begin(), ss.end());
  k_is_.resize(nf, 3 * t);
  k_is_.setFromTriplets(is.begin(), is.end());
}

void TieCondensation::add_stiffness(const std::vector<int>& boundary_slot,
                                    Eigen::MatrixXd& k_add) const {
  const int m3 = static_cast<int>(k_add.rows());
  if (k_add.cols() != m3 || m3 % 3 != 0)
    throw std::invalid_argument("TieCondensation::add_stiffness: K_add must be 3m x 3m");
  const int t = static_cast<int>(tied_nodes_.size());
  Eigen::SparseMatrix<double> j(3 * t, m3);
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(9 * t);
  for (int k = 0; k < t; ++k) {
    for (int v = 0; v < 3; ++v) {
      const int h = host_nodes_[k][v];
      const int slot = h < static_cast<int>(boundary_slot.size()) ? boundary_slot[h] : -1;
      if (slot < 0 || 3 * slot >= m3) {
        throw std::invalid_argument("TieCondensation::add_stiffness: host node " +
                                    std::to_string(h) + " has no boundary slot");
      }
      for (int a = 0; a < 3; ++a) entries.emplace_back(3 * k + a, 3 * slot + a, weights_[k][v]);
    }
  }
  j.setFromTriplets(entries.begin(), entries.end());
  // J^T S_B J = J^T K_ss J - (K_is J)^T K_ii^-1 (K_is J): one solve with 3m right-hand sides.
  const Eigen::SparseMatrix<double> jt = j.transpose();
  const Eigen::SparseMatrix<double> ssj = jt * (k_ss_ * j);
  k_add += Eigen::MatrixXd(ssj);
  if (k_is_.rows() > 0) {
    const Eigen::MatrixXd kj = Eigen::MatrixXd(k_is_ * j);
    Eigen::MatrixXd xi;
    interior_->solve_reduced(kj, xi);
    k_add.noalias() -= kj.transpose() * xi;
  }
}

void TieCondensation::tied_displacement(const Eigen::VectorXd& u_host_m,
                                        Eigen::VectorXd& u_tied_m) const {
  const int t = static_cast<int>(tied_nodes_.size());
  u_tied_m.resize(3 * t);
  for (int k = 0; k < t; ++k) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) u += weights_[k][a] * u_host_m.segment<3>(3 * host_nodes_[k][a]);
    u_tied_m.segment<3>(3 * k) = u;
  }
}

void TieCondensation::displacement(const Eigen::VectorXd& u_host_m, Eigen::VectorXd& u_m,
                                   fem::SolveWorkspace* ws) const {
  Eigen::VectorXd u_s;
  tied_displacement(u_host_m, u_s);
  if (interior_) {
    u_m = ws != nullptr
              ? interior_->solve_prescribed(tied_nodes_, u_s, Eigen::VectorXd(), *ws).displacement_m
              : interior_->solve_prescribed(tied_nodes_, u_s).displacement_m;
  } else {
    u_m.setZero(3 * static_cast<int>(geometry_->num_vertices()));
    for (std::size_t k = 0; k < tied_nodes_.size(); ++k)
      u_m.segment<3>(3 * tied_nodes_[k]) = u_s.segment<3>(3 * static_cast<int>(k));
  }
}

void TieCondensation::add_equivalent_host_load(const Eigen::VectorXd& forces_n,
                                               Eigen::VectorXd& host_load_n) const {
  const int nb3 = 3 * static_cast<int>(geometry_->num_vertices());
  if (forces_n.size() != nb3 || !forces_n.allFinite())
    throw std::invalid_argument("TieCondensation::add_equivalent_host_load: bad force vector");
  const int t = static_cast<int>(tied_nodes_.size());
  Eigen::VectorXd load_s(3 * t);
  for (int k = 0; k < t; ++k) load_s.segment<3>(3 * k) = forces_n.segment<3>(3 * tied_nodes_[k]);
  if (interior_ && k_is_.rows() > 0) {
    const auto& free = interior_->free_dofs();
    Eigen::MatrixXd f_i(static_cast<int>(free.size()), 1), z;
    for (std::size_t r = 0; r < free.size(); ++r) f_i(static_cast<int>(r), 0) = forces_n[free[r]];
    if (f_i.squaredNorm() > 0.0) {
      interior_->solve_reduced(f_i, z);
      load_s.noalias() -= k_is_.transpose() * z.col(0);
    }
  }
  for (int k = 0; k < t; ++k)
    for (int v = 0; v < 3; ++v) {
      const int h = host_nodes_[k][v];
      if (3 * h + 2 >= host_load_n.size())
        throw std::invalid_argument("TieCondensation::add_equivalent_host_load: host load has " +
                                    std::to_string(host_load_n.size()) + " entries, node " +
                                    std::to_string(h) + " needs more");
      host_load_n.segment<3>(3 * h) += weights_[k][v] * load_s.segment<3>(3 * k);
    }
}

void TieCondensation::displacement(const Eigen::VectorXd& u_host_m,
                                   const Eigen::VectorXd& forces_n, Eigen::VectorXd& u_m,
                                   fem::SolveWorkspace* ws) const {
  const int nb3 = 3 * static_cast<int>(geometry_->num_vertices());
  if (forces_n.size() != nb3 || !forces_n.allFinite())
    throw std::invalid_argument("TieCondensation::displacement: bad force vector");
  if (!interior_) {
    displacement(u_host_m, u_m, ws);
    return;
  }
  Eigen::VectorXd u_s;
  tied_displacement(u_host_m, u_s);
  u_m = ws != nullptr ? interior_->solve_prescribed(tied_nodes_, u_s, forces_n, *ws).displacement_m
                      : interior_->solve_prescribed(tied_nodes_, u_s, forces_n).displacement_m;
}

void TieCondensation::add_equivalent_host_loads(const Eigen::MatrixXd& forces_n,
                                                Eigen::MatrixXd& host_load_n,
                                                fem::SolveWorkspace* ws) const {
  const int nb3 = 3 * static_cast<int>(geometry_->num_vertices());
  const Eigen::Index k = forces_n.cols();
  if (forces_n.rows() != nb3 || !forces_n.allFinite() || host_load_n.cols() != k)
    throw std::invalid_argument("TieCondensation::add_equivalent_host_loads: bad force matrix");
  const int t = static_cast<int>(tied_nodes_.size());
  Eigen::MatrixXd load_s(3 * t, k);
  for (int j = 0; j < t; ++j) load_s.middleRows(3 * j, 3) = forces_n.middleRows(3 * tied_nodes_[j], 3);
  if (interior_ && k_is_.rows() > 0) {
    const auto& free = interior_->free_dofs();
    Eigen::MatrixXd f_i(static_cast<int>(free.size()), k), z;
    for (std::size_t r = 0; r < free.size(); ++r) f_i.row(static_cast<int>(r)) = forces_n.row(free[r]);
    if (f_i.squaredNorm() > 0.0) {
      if (ws != nullptr) interior_->solve_reduced(f_i, z, *ws);
      else interior_->solve_reduced(f_i, z);
      load_s.noalias() -= k_is_.transpose() * z;
    }
  }
  for (int j = 0; j < t; ++j)
    for (int v = 0; v < 3; ++v) {
      const int h = host_nodes_[j][v];
      if (3 * h + 2 >= host_load_n.rows())
        throw std::invalid_argument("TieCondensation::add_equivalent_host_loads: host load has " +
                                    std::to_string(host_load_n.rows()) + " rows, node " +
                                    std::to_string(h) + " needs more");
      host_load_n.middleRows(3 * h, 3) += weights_[j][v] * load_s.middleRows(3 * j, 3);
    }
}

void TieCondensation::displacements(const Eigen::MatrixXd& u_host_m, const Eigen::MatrixXd& forces_n,
                                    Eigen::MatrixXd& u_m, fem::SolveWorkspace* ws) const {
  const int nb3 = 3 * static_cast<int>(geometry_->num_vertices());
  const Eigen::Index k = u_host_m.cols();
  if ((forces_n.cols() != 0 && (forces_n.cols() != k || forces_n.rows() != nb3)) ||
      !u_host_m.allFinite())
    throw std::invalid_argument("TieCondensation::displacements: bad displacement or force matrix");
  const int t = static_cast<int>(tied_nodes_.size());
  Eigen::MatrixXd u_s(3 * t, k);
  for (int j = 0; j < t; ++j) {
    u_s.middleRows(3 * j, 3).setZero();
    for (int a = 0; a < 3; ++a)
      u_s.middleRows(3 * j, 3) += weights_[j][a] * u_host_m.middleRows(3 * host_nodes_[j][a], 3);
  }
  u_m.setZero(nb3, k);
  for (int j = 0; j < t; ++j) u_m.middleRows(3 * tied_nodes_[j], 3) = u_s.middleRows(3 * j, 3);
  if (!interior_) return;
  // B's free interior (its exposed nodes included): K_ii u_i = f_i - K_is u_s.
  const auto& free = interior_->free_dofs();
  Eigen::MatrixXd rhs = -(k_is_ * u_s), z;
  if (forces_n.cols() != 0)
    for (std::size_t r = 0; r < free.size(); ++r) rhs.row(static_cast<int>(r)) += forces_n.row(free[r]);
  if (ws != nullptr) interior_->solve_reduced(rhs, z, *ws);
  else interior_->solve_reduced(rhs, z);
  for (std::size_t r = 0; r < free.size(); ++r) u_m.row(free[r]) = z.row(static_cast<int>(r));
}

double TieCondensation::residual(const Eigen::VectorXd& u_host_m,
                                 const Eigen::VectorXd& u_embedded_m) const {
  double worst = 0.0;
  for (std::size_t k = 0; k < tied_nodes_.size(); ++k) {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    for (int a = 0; a < 3; ++a) u += weights_[k][a] * u_host_m.segment<3>(3 * host_nodes_[k][a]);
    worst = std::max(worst, (u - u_embedded_m.segment<3>(3 * tied_nodes_[k])).norm());
  }
  return worst;
}

}  // namespace neurosim::interaction
