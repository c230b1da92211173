// Cache of a body's coupled compliance columns at its contact nodes (the contact-compliance
// cache): L[contact dofs, slot] (3s x 3 per touched node, unit m/N), filled on first touch (block
// solves, milliseconds), all at load, or ahead of the tool by a ColumnWorker (column_worker.hpp);
// with sliding rows also J_A L[:, slot] (rows x 3); and, on request, the full columns L[:, slot]
// (3N x 3, memory!) so the host field for contact forces is a sum of columns instead of a sparse
// solve. It changes during stepping, so it belongs to the per-step State, never to the constant
// CoupledBody it reads.
//
// One writer, one reader: the writer (the step itself when it solves synchronously, or the
// ColumnWorker's thread) fills a slot's storage, then marks it ready with a release store; the
// reader (the step) reads a slot only after has(slot) saw it ready (acquire). A ready slot is
// never changed while it is ready, so the hand-over is lock-free and the step never waits for
// the writer.
//
// Bounded (the column worker): the writer may free ready slots, but only those the reader gave
// up, by a three-state mailbox (never a lock, never a wait on either side):
//   writer: propose_eviction(victims)  -> the victims listed, state "proposed" (release)
//   reader: grant_eviction(holds)      -> at the start of a step, before it reads any column:
//           each victim the step does not hold (holds(slot) false: not a force slot of the last
//           answer, not in a relaxing body's history) is marked not ready; state "granted"
//   writer: reclaim()                  -> frees the granted slots' storage; state "idle"
// After the grant the reader reaches a slot only through has() (false now), so the writer frees
// storage nobody reads; a freed slot may be solved and published again later.
#pragma once

#include "server/interaction/coupled_body.hpp"

#include <Eigen/Core>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

namespace neurosim::interaction {

class ContactColumns {
 public:
  using Columns = Eigen::Matrix<double, Eigen::Dynamic, 3>;

  // body must be finalized and outlive the cache.
  explicit ContactColumns(const CoupledBody& body, bool keep_full_columns = false);

  int num_slots() const { return static_cast<int>(columns_.size()); }
  // Whether the columns of a slot are ready (any thread; acquire: its storage may then be read).
  bool has(int slot) const { return ready_[slot].load(std::memory_order_acquire) != 0; }
  // Slots ready now (any thread).
  std::size_t size() const { return count_.load(std::memory_order_acquire); }
  // Bytes of column storage one ready slot holds (the contact columns, the sliding rows' and the
  // full columns when kept), unit byte.
  std::size_t bytes_per_slot() const { return bytes_per_slot_; }
  // Slots freed so far by reclaim() (any thread).
  std::uint64_t evicted() const { return evicted_.load(std::memory_order_acquire); }

  // Eviction (see above). Most victims of one proposal.
  static constexpr int kMaxVictims = 64;
  // Writer: proposes up to kMaxVictims ready slots for eviction; false (nothing done) while an
  // earlier proposal is not reclaimed yet. Throws std::invalid_argument for a slot out of range.
  bool propose_eviction(const std::vector<int>& victims);
  // Reader (the step, before it reads any column in a step): grants each proposed slot for which
  // holds(slot) is false by marking it not ready. Never allocates; O(victims).
  template <class Holds>
  void grant_eviction(const Holds& holds) {
    if (mailbox_.load(std::memory_order_acquire) != kProposed) return;
    std::size_t n = 0;
    for (int k = 0; k < num_victims_; ++k) {
      const int s = victims_[k];
      granted_[k] = !holds(s) && ready_[s].load(std::memory_order_relaxed) != 0;
      if (granted_[k]) {
        ready_[s].store(0, std::memory_order_relaxed);
        ++n;
      }
    }
    if (n > 0) count_.fetch_sub(n, std::memory_order_acq_rel);
    mailbox_.store(kGranted, std::memory_order_release);
  }
  // Writer: frees the storage of the slots granted (unless the writer published one again since
  // the grant); returns how many (0 if no grant yet). Call it before each ensure().
  int reclaim();
  // Iterations the ITERATIVE baseline's coupling needed for the columns computed so far (read it
  // from the writer's thread, or once the writer is stopped).
  const IterativeReport& iterative_report() const { return iterations_; }
  // Writer: computes the columns of the given slots that are missing (block solves; allocates)
  // with the cache's own solve scratch (synchronous use: the step's) or the caller's `ws` (a
  // ColumnWorker's), and publishes each. Returns how many it computed. Throws
  // std::invalid_argument for a slot out of range.
  int ensure(const std::vector<int>& slots);
  int ensure(const std::vector<int>& slots, fem::SolveWorkspace& ws);

  // Coupled compliance block L(i, j) (3x3, unit m/N) between contact slots i and j; the
  // columns of j must be ready.
  Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> block(int slot_i, int slot_j) const {
    return Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
        columns_[slot_j].data() + 9 * static_cast<std::ptrdiff_t>(slot_i));
  }
  // J_A L[:, slot] (sliding rows x 3) of a ready slot, unit m/N.
  const Columns& sliding_block(int slot) const { return sliding_columns_[slot]; }
  // u_host = sum_k L[:, slot_k] f_k from the full columns; false if one is missing or full
  // columns are not kept.
  bool full_field(const std::vector<int>& slots, const std::vector<mesh::Vec3>& forces_n,
                  Eigen::VectorXd& u_host_m) const;

 private:
  const CoupledBody* body_;
  // The State's own solve scratch for synchronous first touches: locks nothing in the Model.
  std::unique_ptr<fem::SolveWorkspace> ws_ = std::make_unique<fem::SolveWorkspace>();
  IterativeReport iterations_;  // the ITERATIVE baseline's iterations for these columns (writer)
  bool keep_full_;
  // Per contact slot (sized at construction, never reallocated): written once by the writer
  // before ready_[slot] is set.
  // L[contact dofs, slot], row-major: the 3 x 3 block of a slot pair is 9 contiguous doubles
  // (the step reads blocks: positions, Delassus, forces).
  using Blocks = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
  std::vector<Blocks> columns_;
  std::vector<Columns> full_columns_;     // L[:, slot] (keep_full_)
  std::vector<Columns> sliding_columns_;  // J_A L[:, slot] (sliding rows)
  std::unique_ptr<std::atomic<unsigned char>[]> ready_;
  std::atomic<std::size_t> count_{0};
  std::size_t bytes_per_slot_{0};
  // Eviction mailbox: victims_ and num_victims_ written by the writer before kProposed, granted_
  // by the reader before kGranted.
  static constexpr int kIdle = 0, kProposed = 1, kGranted = 2;
  std::atomic<int> mailbox_{kIdle};
  int victims_[kMaxVictims]{};
  bool granted_[kMaxVictims]{};
  int num_victims_{0};
  std::atomic<std::uint64_t> evicted_{0};
};

}  // namespace neurosim::interaction
