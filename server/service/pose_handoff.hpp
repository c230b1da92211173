// Newest-pose handoff from the DDS thread (one producer) to the step thread (one consumer):
// a PoseSample per station slot in a common::TripleBuffer, so neither side ever blocks or waits
// for the other.
#pragma once

#include "common/triple_buffer.hpp"

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

}  // namespace neurosim::service
