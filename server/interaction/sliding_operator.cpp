// SlidingOperator: J_A and W_A = J_A L J_A^T of a body's sliding rows (see the header).
#include "server/interaction/sliding_operator.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace neurosim::interaction {

void check_sliding_rows(const std::vector<HostSlidingRow>& rows, int host_vertices,
                        const std::string& what) {
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const auto& r = rows[k];
    double sum = 0.0;
    for (int a = 0; a < 3; ++a) {
      if (r.nodes[a] < 0 || r.nodes[a] >= host_vertices || !std::isfinite(r.weights[a]) ||
          r.weights[a] < -1e-12) {
        throw std::invalid_argument(what + ": bad sliding row " + std::to_string(k) +
                                    " (host node or weight)");
      }
      sum += r.weights[a];
    }
    if (std::abs(sum - 1.0) > 1e-9 || !r.normal.allFinite() ||
        std::abs(r.normal.norm() - 1.0) > 1e-9) {
      throw std::invalid_argument(what + ": sliding row " + std::to_string(k) +
                                  " has weights summing to " + std::to_string(sum) +
                                  " or a normal that is not unit");
    }
  }
}

SlidingOperator::SlidingOperator(SlidingOperatorDefinition def) {
  if (def.host == nullptr || !def.coupled_solve || def.block_columns < 1) {
    throw std::invalid_argument(
        "SlidingOperator: needs the host's solver, a coupled solve and block_columns >= 1");
  }
  const fem::StaticSolver& host = *def.host;
  check_sliding_rows(def.rows, host.num_nodes(), "SlidingOperator");
  rows_ = std::move(def.rows);
  const int ns = size();
  // J_A on the free dofs: row k = sum_a w_a n^T at A's nodes (fixed dofs do not move).
  const auto& reduced = host.reduced_index();
  const int nf = host.num_free_dofs();
  std::vector<Eigen::Triplet<double>> entries;
  entries.reserve(9 * rows_.size());
  for (int k = 0; k < ns; ++k) {
    const auto& r = rows_[k];
    for (int a = 0; a < 3; ++a)
      for (int d = 0; d < 3; ++d) {
        const int red = reduced[3 * r.nodes[a] + d];
        if (red >= 0 && r.weights[a] * r.normal[d] != 0.0)
          entries.emplace_back(k, red, r.weights[a] * r.normal[d]);
      }
  }
  j_.resize(ns, nf);
  j_.setFromTriplets(entries.begin(), entries.end());
  // W_A = J_A L J_A^T by block solves with the rows' force patterns as right-hand sides.
  w_.setZero(ns, ns);
  Eigen::MatrixXd rhs, x;
  for (int first = 0; first < ns; first += def.block_columns) {
    const int n = std::min(def.block_columns, ns - first);
    rhs = Eigen::MatrixXd(j_.middleRows(first, n).transpose());
    def.coupled_solve(rhs, x);
    w_.middleCols(first, n).noalias() = j_ * x;
  }
  w_ = (0.5 * (w_ + w_.transpose())).eval();
  if (!w_.allFinite()) throw std::runtime_error("SlidingOperator: W_A is not finite");
}

Eigen::MatrixXd SlidingOperator::apply(const Eigen::Ref<const Eigen::MatrixXd>& x) const {
  if (x.rows() != j_.cols()) {
    throw std::invalid_argument("SlidingOperator::apply: " + std::to_string(x.rows()) +
                                " rows, the host has " + std::to_string(j_.cols()) + " free dofs");
  }
  return j_ * x;
}

}  // namespace neurosim::interaction
