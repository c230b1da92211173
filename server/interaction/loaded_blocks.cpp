#include "server/interaction/loaded_blocks.hpp"

#include <algorithm>

namespace neurosim::interaction {

void LoadedBlocks::reserve(int slots, int capacity) {
  capacity_ = std::max(0, std::min(slots, capacity));
  index_.assign(static_cast<std::size_t>(std::max(0, slots)), -1);
  slots_.clear();
  slots_.reserve(static_cast<std::size_t>(capacity_));
  const std::size_t n = static_cast<std::size_t>(capacity_) * static_cast<std::size_t>(capacity_);
  blocks_.reset(new double[9 * n]);  // not initialised: a block is written before it is read
  copied_.assign(n, 0);
  evicted_ = 0;
}

void LoadedBlocks::refresh(const ContactColumns& cols) {
  const std::uint64_t e = cols.evicted();
  if (e == evicted_) return;
  evicted_ = e;
  clear();
}

void LoadedBlocks::clear() {
  const std::size_t used = slots_.size(), cap = static_cast<std::size_t>(capacity_);
  for (std::size_t i = 0; i < used; ++i)
    std::fill(copied_.begin() + static_cast<std::ptrdiff_t>(i * cap),
              copied_.begin() + static_cast<std::ptrdiff_t>(i * cap + used), 0);
  for (const int s : slots_) index_[static_cast<std::size_t>(s)] = -1;
  slots_.clear();
}

}  // namespace neurosim::interaction
