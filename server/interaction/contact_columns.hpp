// Cache of a body's coupled compliance columns at its contact nodes (the contact-compliance
// cache): L[contact dofs, slot] (3s x 3 per touched node, unit m/N), filled on first touch (block
// solves, milliseconds) or all at load; with sliding rows also J_A L[:, slot] (rows x 3); and,
// on request, the full columns L[:, slot] (3N x 3, memory!) so the host field for contact forces
// is a sum of columns instead of a sparse solve. It changes during stepping, so it belongs to the
// per-step State, never to the constant CoupledBody it reads.
#pragma once

#include "server/interaction/coupled_body.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <memory>
#include <vector>

namespace neurosim::interaction {

class ContactColumns {
 public:
  using Columns = Eigen::Matrix<double, Eigen::Dynamic, 3>;

  // body must be finalized and outlive the cache.
  explicit ContactColumns(const CoupledBody& body, bool keep_full_columns = false);

  bool has(int slot) const { return column_of_[slot] >= 0; }
  std::size_t size() const { return columns_.size(); }
  // Iterations the ITERATIVE baseline's coupling needed for the columns computed so far.
  const IterativeReport& iterative_report() const { return iterations_; }
  // Computes the columns of the given slots that are missing (block solves; allocates).
  // Throws std::invalid_argument for a slot out of range.
  void ensure(const std::vector<int>& slots);

  // Coupled compliance block L(i, j) (3x3, unit m/N) between contact slots i and j; the
  // columns of j must be cached.
  Eigen::Matrix3d block(int slot_i, int slot_j) const {
    return columns_[column_of_[slot_j]].block<3, 3>(3 * slot_i, 0);
  }
  // J_A L[:, slot] (sliding rows x 3) of a cached slot, unit m/N.
  const Columns& sliding_block(int slot) const { return sliding_columns_[column_of_[slot]]; }
  // u_host = sum_k L[:, slot_k] f_k from the full columns; false if one is missing or full
  // columns are not kept.
  bool full_field(const std::vector<int>& slots, const std::vector<mesh::Vec3>& forces_n,
                  Eigen::VectorXd& u_host_m) const;

 private:
  const CoupledBody* body_;
  // The State's own solve scratch: a first touch inside the step locks nothing in the Model.
  std::unique_ptr<fem::SolveWorkspace> ws_ = std::make_unique<fem::SolveWorkspace>();
  IterativeReport iterations_;  // the ITERATIVE baseline's iterations for these columns
  bool keep_full_;
  std::vector<int> column_of_;  // contact slot -> index in columns_ or -1
  std::vector<Columns> columns_;          // L[contact dofs, slot]
  std::vector<Columns> full_columns_;     // L[:, slot], same order (keep_full_)
  std::vector<Columns> sliding_columns_;  // J_A L[:, slot], same order (sliding rows)
};

}  // namespace neurosim::interaction
