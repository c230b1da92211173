// Lock-free single-producer single-consumer hand-off of the newest value (triple buffer): the
// DDS thread writes ContactModels, the 1 kHz loop takes the newest without ever blocking.
#pragma once

#include <atomic>
#include <cstdint>

namespace neurosim::haptic {

template <class T>
class LatestSlot {
 public:
  // Producer: publish v (overwrites an unread older value).
  void write(const T& v) {
    buf_[back_] = v;
    const std::uint8_t old =
        middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel);
    back_ = old & kIndex;
  }
  // Consumer: copies the newest value into out if one arrived since the last take.
  bool take(T& out) {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return false;
    const std::uint8_t old = middle_.exchange(front_, std::memory_order_acq_rel);
    front_ = old & kIndex;
    out = buf_[front_];
    return true;
  }

 private:
  static constexpr std::uint8_t kFresh = 4;
  static constexpr std::uint8_t kIndex = 3;
  T buf_[3]{};
  std::atomic<std::uint8_t> middle_{1};
  std::uint8_t back_ = 0;   // producer-owned
  std::uint8_t front_ = 2;  // consumer-owned
};

}  // namespace neurosim::haptic
