// A compact copy of one body's coupled compliance blocks C(k, s) (ContactColumns::block, 3 x 3,
// unit m/N) between the nodes the contact step loads, kept across steps. The step's loaded nodes
// move little from one step to the next, while their blocks lie one per column of the cache, 72
// bytes each in columns of 72 bytes per contact slot: the sums over them (normal_turn's U_k =
// -sum_s C_ks f_s, every loaded node against every force slot) waited on memory block by block.
// Here each node held has an index, and the blocks of one node against all the others lie in one
// row, in the indices' order (the nodes of one step are mostly adjacent indices). A block is
// copied bit for bit from the columns on its first use, so a sum over these blocks is the same
// as over the columns'.
//
// Sized once (reserve; the block storage's pages are touched only where used), never
// reallocated: a use assigns indices to new nodes, and when they run out the copy starts over
// (clear). A column solved again after an eviction may differ in its last bits, so the copy
// starts over too when the columns evicted a slot since its last use (refresh).
#pragma once

#include "server/interaction/contact_columns.hpp"

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <vector>

namespace neurosim::interaction {

class LoadedBlocks {
 public:
  // slots: the body's contact slots; capacity: the most nodes held at once (allocates).
  void reserve(int slots, int capacity);
  int capacity() const { return capacity_; }
  // Before a use: starts over when the columns evicted slots since the last use.
  void refresh(const ContactColumns& cols);
  // Forgets every node and block.
  void clear();
  // The index of a contact slot's node, assigned if new; -1 when every index is taken.
  int index(int slot) {
    int& at = index_[static_cast<std::size_t>(slot)];
    if (at < 0) {
      if (static_cast<int>(slots_.size()) == capacity_) return -1;
      at = static_cast<int>(slots_.size());
      slots_.push_back(slot);
    }
    return at;
  }
  // C(slot of i, slot of j), row-major, for indices i and j; column j's slot must be ready.
  const double* block(const ContactColumns& cols, int i, int j) {
    const std::size_t at = static_cast<std::size_t>(i) * static_cast<std::size_t>(capacity_) +
                           static_cast<std::size_t>(j);
    double* b = blocks_.get() + 9 * at;
    if (!copied_[at]) {
      std::memcpy(b, cols.block(slots_[i], slots_[j]).data(), 9 * sizeof(double));
      copied_[at] = 1;
    }
    return b;
  }
  // The blocks of index i against indices j, j + 1, ... (row i), for fetching ahead.
  const double* row(int i) const {
    return blocks_.get() + 9 * static_cast<std::size_t>(i) * static_cast<std::size_t>(capacity_);
  }

 private:
  int capacity_{0};
  std::vector<int> index_;  // per contact slot: its index, else -1
  std::vector<int> slots_;  // per index: its contact slot
  std::unique_ptr<double[]> blocks_;  // capacity^2 blocks of 9, row i at 9 capacity i
  std::vector<unsigned char> copied_;  // per block: copied from the columns
  std::uint64_t evicted_{0};  // the columns' evictions at the last use
};

}  // namespace neurosim::interaction
