// Lock-free hand-off of the newest value from one producer thread to one consumer thread (a
// triple buffer): neither side ever blocks or waits for the other, a value the consumer has not
// taken yet is overwritten by a newer one, and the consumer never sees a torn value.
//
//   producer: publish(v)                    consumer: if (b.consume()) use(b.newest());
//                                                      or: T v; if (b.take(v)) use(v);
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

namespace neurosim::common {

template <class T>
class TripleBuffer {
 public:
  // Producer: copies v into its back buffer and swaps that into the middle, marked fresh.
  void publish(const T& v) {
    buf_[back_] = v;
    back_ = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel) &
            kIndex;
  }

  // Consumer: takes the middle buffer if it is fresh; returns whether it was (then newest()
  // changed).
  bool consume() {
    if ((middle_.load(std::memory_order_acquire) & kFresh) == 0) return false;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return true;
  }

  // Consumer: the newest value taken by consume() (a default-constructed T before the first).
  const T& newest() const { return buf_[front_]; }

  // Consumer: copies the newest value into out if one arrived since the last take/consume.
  bool take(T& out) {
    if (!consume()) return false;
    out = newest();
    return true;
  }

 private:
  static constexpr std::uint8_t kIndex = 3;
  static constexpr std::uint8_t kFresh = 4;
  std::array<T, 3> buf_{};
  std::atomic<std::uint8_t> middle_{1};
  std::uint8_t back_{0};   // producer only
  std::uint8_t front_{2};  // consumer only
};

}  // namespace neurosim::common
