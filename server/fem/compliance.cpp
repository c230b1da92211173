#include "server/fem/compliance.hpp"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace neurosim::fem {

Compliance::Compliance(const StaticSolver& solver, const ComplianceOptions& options)
    : solver_(solver),
      options_(options),
      slot_(solver.num_dofs(), -1),
      zero_(Eigen::VectorXd::Zero(solver.num_dofs())) {
  if (options_.block_columns < 1) {
    throw std::invalid_argument("Compliance: block_columns must be >= 1, got " +
                                std::to_string(options_.block_columns));
  }
}

void Compliance::check_dof(int dof) const {
  if (dof < 0 || dof >= solver_.num_dofs()) {
    throw std::invalid_argument("Compliance: dof " + std::to_string(dof) + " out of range [0, " +
                                std::to_string(solver_.num_dofs()) + ")");
  }
}

const Eigen::VectorXd* Compliance::find_column(int dof) const {
  if (dof < 0 || dof >= static_cast<int>(slot_.size())) {
    return nullptr;
  }
  if (solver_.reduced_index()[dof] < 0) {
    return &zero_;
  }
  const int s = slot_[dof];
  return s < 0 ? nullptr : columns_[s].get();
}

const Eigen::VectorXd& Compliance::column(int dof) {
  check_dof(dof);
  if (const Eigen::VectorXd* c = find_column(dof)) {
    return *c;
  }
  Eigen::VectorXd f = Eigen::VectorXd::Zero(solver_.num_dofs());
  f[dof] = 1.0;
  auto col = std::make_unique<Eigen::VectorXd>();
  solver_.solve(f, *col);
  slot_[dof] = static_cast<int>(columns_.size());
  columns_.push_back(std::move(col));
  return *columns_.back();
}

void Compliance::precompute(const std::vector<int>& dofs) {
  std::vector<int> missing;
  for (int d : dofs) {
    check_dof(d);
    if (!find_column(d)) {
      missing.push_back(d);
    }
  }
  std::sort(missing.begin(), missing.end());
  missing.erase(std::unique(missing.begin(), missing.end()), missing.end());
  const auto& reduced = solver_.reduced_index();
  const auto& free_dofs = solver_.free_dofs();
  const int nf = solver_.num_free_dofs();
  Eigen::MatrixXd rhs, x;
  for (std::size_t first = 0; first < missing.size(); first += options_.block_columns) {
    const int m =
        static_cast<int>(std::min<std::size_t>(options_.block_columns, missing.size() - first));
    // Unit right-hand sides: one CHOLMOD call solves all of them (BLAS-3 in the supernodes).
    rhs.setZero(nf, m);
    for (int c = 0; c < m; ++c) {
      rhs(reduced[missing[first + c]], c) = 1.0;
    }
    solver_.solve_reduced(rhs, x);
    for (int c = 0; c < m; ++c) {
      auto col = std::make_unique<Eigen::VectorXd>(Eigen::VectorXd::Zero(solver_.num_dofs()));
      for (int r = 0; r < nf; ++r) {
        (*col)[free_dofs[r]] = x(r, c);
      }
      slot_[missing[first + c]] = static_cast<int>(columns_.size());
      columns_.push_back(std::move(col));
    }
  }
}

void Compliance::precompute_nodes(const std::vector<int>& nodes) {
  std::vector<int> dofs;
  dofs.reserve(3 * nodes.size());
  for (int v : nodes) {
    for (int a = 0; a < 3; ++a) {
      dofs.push_back(3 * v + a);
    }
  }
  precompute(dofs);
}

Eigen::MatrixXd Compliance::block(const std::vector<int>& nodes) {
  precompute_nodes(nodes);
  Eigen::MatrixXd out(3 * nodes.size(), 3 * nodes.size());
  block_from_cache(nodes, out);
  return out;
}

void Compliance::block_from_cache(const std::vector<int>& nodes, Eigen::MatrixXd& out) const {
  const Eigen::Index m = 3 * static_cast<Eigen::Index>(nodes.size());
  for (int v : nodes) {
    if (v < 0 || v >= solver_.num_nodes()) {
      throw std::invalid_argument("Compliance::block: node " + std::to_string(v) +
                                  " out of range [0, " + std::to_string(solver_.num_nodes()) + ")");
    }
  }
  if (out.rows() != m || out.cols() != m) {
    out.resize(m, m);
  }
  for (Eigen::Index c = 0; c < m; ++c) {
    const int node_c = nodes[c / 3];
    const Eigen::VectorXd* col = find_column(3 * node_c + static_cast<int>(c % 3));
    if (!col) {
      throw std::logic_error("Compliance::block_from_cache: column of node " +
                             std::to_string(node_c) + " not cached (call precompute_nodes first)");
    }
    for (Eigen::Index r = 0; r < m; ++r) {
      out(r, c) = (*col)[3 * nodes[r / 3] + r % 3];
    }
  }
}

std::size_t Compliance::cache_bytes() const {
  return columns_.size() * static_cast<std::size_t>(solver_.num_dofs()) * sizeof(double);
}

void Compliance::clear() {
  columns_.clear();
  std::fill(slot_.begin(), slot_.end(), -1);
}

}  // namespace neurosim::fem
