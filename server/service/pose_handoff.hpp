// Newest-pose handoff from the DDS thread (one producer) to the step thread (one consumer):
// an atomic triple buffer, so neither side ever blocks or waits for the other.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>

namespace neurosim::service {

// One accepted tool sample as the step thread needs it.
struct PoseSample {
  std::uint64_t sequence{0};        // ToolState.sequence_number
  std::int64_t source_time_ns{0};   // ToolState.source_time_ns, unit ns
  double position_m[3]{0, 0, 0};    // tool tip, unit m
  double orientation[4]{1, 0, 0, 0};  // unit quaternion (w, x, y, z)
  int tool{0};                      // index into scene.tools()
};

template <class T>
class TripleBuffer {
 public:
  // Producer: copies v into its back buffer and swaps it into the middle (marked fresh).
  void publish(const T& v) {
    buf_[back_] = v;
    back_ = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel) &
            kIndex;
  }
  // Consumer: takes the middle buffer if fresh; returns whether it was (then newest() changed).
  bool consume() {
    if ((middle_.load(std::memory_order_relaxed) & kFresh) == 0) return false;
    front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return true;
  }
  // Consumer: the newest value taken by consume().
  const T& newest() const { return buf_[front_]; }

 private:
  static constexpr std::uint8_t kIndex = 3;
  static constexpr std::uint8_t kFresh = 4;
  std::array<T, 3> buf_{};
  std::atomic<std::uint8_t> middle_{1};
  std::uint8_t back_{0};   // producer only
  std::uint8_t front_{2};  // consumer only
};

}  // namespace neurosim::service
