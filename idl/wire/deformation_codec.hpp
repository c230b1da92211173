// Deformation frames (idl/neurosim.idl): FULL float32 frames every full_frame_period frames and
// QUANTIZED_DELTA frames in between (int16 per component times delta_scale_m, relative to the
// last FULL frame), so a late-joining viewer can decode within one period.
#pragma once

#include "idl/wire/types.hpp"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace neurosim::wire {

// Largest displacement component the encoder accepts, unit m: half the float32 range, so that
// every delta and every decoded sum stays finite.
inline constexpr double kMaxEncodedDisplacementM = 1.7e38;

struct DeformationEncoderOptions {
  std::uint32_t full_frame_period = 30;  // frames; at a 30 Hz viewer rate one FULL frame per s
  bool quantize = true;                  // false: every frame FULL
};

// One per mesh on the server. Model: mesh id and vertex count; State: the last FULL frame.
class DeformationEncoder {
 public:
  DeformationEncoder(std::string mesh_id, std::size_t vertex_count, std::uint32_t topology_revision,
                     DeformationEncoderOptions options = {});

  // Fills out (reusing its buffers) with the next frame of displacements u_m (3 per vertex, m).
  // Throws std::invalid_argument on a wrong size or a component that is not finite or beyond
  // kMaxEncodedDisplacementM (names the vertex).
  void encode(const double* u_m, std::size_t n, std::uint64_t server_step,
              std::int64_t server_time_ns, neurosim_Deformation& out);
  // Make the next frame FULL (e.g. a new viewer matched).
  void force_full_next() { force_full_ = true; }
  std::uint64_t frames() const { return frame_; }

 private:
  std::string mesh_id_;
  std::size_t vertex_count_;
  std::uint32_t revision_;
  DeformationEncoderOptions opt_;
  std::vector<float> base_;  // last FULL frame, as sent (float32)
  std::uint64_t frame_ = 0;  // frames encoded so far
  std::uint64_t base_frame_ = 0;
  bool have_base_ = false;
  bool force_full_ = false;
};

// One per mesh on a viewer: keeps the last FULL frame to add deltas to.
class DeformationDecoder {
 public:
  // Writes the displacements (3 per vertex, m) into u_m. Returns false when the frame cannot be
  // decoded yet (a delta whose FULL base frame was not received: wait for the next FULL one).
  // Throws std::invalid_argument on an inconsistent frame (sizes, encoding, a negative or
  // non-finite delta_scale_m) or one that would give non-finite displacements (a FULL frame with
  // NaN or Inf, a delta that overflows float); a refused FULL frame leaves the base as it was.
  bool decode(const neurosim_Deformation& in, std::vector<float>& u_m);

 private:
  std::vector<float> base_;
  std::uint64_t base_frame_ = 0;
  bool have_base_ = false;
};

}  // namespace neurosim::wire
