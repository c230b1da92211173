// Compliance L = K^-1 (with the fixed nodes eliminated), column by column from the factor of a
// StaticSolver (paper Eq. 4: u = L f), cached; dense blocks L_SS for node sets.
#pragma once

#include "server/fem/static_solver.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <memory>
#include <vector>

namespace neurosim::fem {

struct ComplianceOptions {
  // Right-hand sides per CHOLMOD block solve when many columns are computed at once
  // (bench/fem_bench: blocks of 32-300 beat one-by-one solves by ~1.5x on 1k-dof meshes and
  // 3-5x on 15k-dof meshes; 64 is at or near the best everywhere).
  int block_columns{64};
};

// Thread safety: column()/precompute()/block() insert into the cache and must not run
// concurrently with anything else on the same Compliance. find_column() and
// block_from_cache() only read: once the needed columns are precomputed, any number of
// threads may call them at the same time.
class Compliance {
 public:
  // `solver` must outlive this object and stay where it is (not moved from).
  explicit Compliance(const StaticSolver& solver, const ComplianceOptions& options = {});

  // Column L[:, dof] (3N, unit m/N): displacements for a unit force at `dof` (= 3 node + axis).
  // Zero for dofs of fixed nodes. One solve on first use, then cached; the reference stays
  // valid for the lifetime of this object (until clear()).
  const Eigen::VectorXd& column(int dof);
  // Cached column or nullptr; never computes or allocates.
  const Eigen::VectorXd* find_column(int dof) const;
  // Computes every missing column of `dofs` by block solves of options.block_columns.
  void precompute(const std::vector<int>& dofs);
  // The same for all three dofs of each node.
  void precompute_nodes(const std::vector<int>& nodes);

  // Dense block L_SS (3|S| x 3|S|, unit m/N), node-major: row/col 3k + a is node S[k], axis a.
  // Missing columns are computed by block solves and cached.
  Eigen::MatrixXd block(const std::vector<int>& nodes);
  // From cached columns only, into a caller-sized matrix: no allocation once `out` has the
  // right size. Throws std::logic_error if a column is not cached.
  void block_from_cache(const std::vector<int>& nodes, Eigen::MatrixXd& out) const;

  std::size_t num_cached() const { return columns_.size(); }
  std::size_t cache_bytes() const;  // memory of the cached columns, unit byte
  const StaticSolver& solver() const { return solver_; }
  const FactorInfo& factor_info() const { return solver_.factor_info(); }
  void clear();

 private:
  const StaticSolver& solver_;
  ComplianceOptions options_;
  std::vector<int> slot_;  // dof -> index in columns_, or -1
  std::vector<std::unique_ptr<Eigen::VectorXd>> columns_;
  Eigen::VectorXd zero_;  // the column of every fixed dof

  void check_dof(int dof) const;
};

}  // namespace neurosim::fem
