// FieldColumns: the full coupled compliance columns L[:, slot] (3N x 3 per contact node, unit
// m/N; N host vertices, ties folded in as in CoupledBody::solve_contact_columns) of the nodes
// that carried contact forces in recent fields, kept by whoever computes the fields (a
// FieldSnapshot: the field thread), so the host field of contact forces alone is a sum of
// columns, u = sum_k L[:, slot_k] f_k, instead of a sparse solve of the whole host.
//
// A node's full columns come from one block solve the first time a field needs them (its
// missing nodes together: about the cost of one field solve, more with many new nodes); while
// the loaded nodes stay the same (a held or slowly moving tool) each field is a sum over them.
// Bounded: at most capacity nodes (3N x 3 doubles each: 3.9 MB on the 3 mm brain), the least
// recently used evicted; a field with more loaded nodes than that is refused (the caller
// solves). Not shared: one thread uses it (the column worker's compact columns stay in the
// State, contact_columns.hpp).
#pragma once

#include "server/interaction/coupled_body.hpp"

#include <Eigen/Core>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace neurosim::interaction {

class FieldColumns {
 public:
  using Vec3 = Eigen::Vector3d;

  // body must be finalized and outlive this; capacity_slots >= 1 (std::invalid_argument).
  FieldColumns(const CoupledBody& body, std::size_t capacity_slots);

  // Bytes of one node's full columns on `body`, unit byte.
  static std::size_t bytes_per_slot(const CoupledBody& body);

  // u_host_m = sum_k L[:, slots_k] forces_n_k (3N, unit m), solving the columns of the slots not
  // kept yet with `ws` (allocates) and evicting the least recently used beyond the capacity.
  // false (u untouched) when the slots are more than the capacity. Throws std::invalid_argument
  // for a slot out of range or sizes that differ.
  bool field(const std::vector<int>& slots, const std::vector<Vec3>& forces_n,
             Eigen::VectorXd& u_host_m, fem::SolveWorkspace& ws);

  std::size_t size() const { return kept_; }
  std::size_t capacity() const { return capacity_; }
  std::uint64_t columns_solved() const { return solved_; }  // nodes solved so far
  std::uint64_t evicted() const { return evicted_; }

 private:
  using Columns = Eigen::Matrix<double, Eigen::Dynamic, 3>;
  const CoupledBody* body_;
  std::size_t capacity_;
  std::vector<Columns> full_;           // per contact slot (empty: not kept)
  std::vector<std::uint64_t> last_use_; // per contact slot: the field that last used it
  std::vector<int> kept_slots_;         // the slots kept
  std::uint64_t fields_{0};
  std::size_t kept_{0};
  std::uint64_t solved_{0}, evicted_{0};
  std::vector<int> missing_;
  Eigen::MatrixXd x_;  // block solve scratch
};

}  // namespace neurosim::interaction
