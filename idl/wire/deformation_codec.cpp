#include "idl/wire/deformation_codec.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace neurosim::wire {

DeformationEncoder::DeformationEncoder(std::string mesh_id, std::size_t vertex_count,
                                       std::uint32_t topology_revision,
                                       DeformationEncoderOptions options)
    : mesh_id_(std::move(mesh_id)),
      vertex_count_(vertex_count),
      revision_(topology_revision),
      opt_(options),
      base_(3 * vertex_count, 0.0f) {
  if (opt_.full_frame_period == 0)
    throw std::invalid_argument("DeformationEncoder " + mesh_id_ + ": full_frame_period is 0");
  if (3 * vertex_count > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("DeformationEncoder " + mesh_id_ + ": too many vertices");
}

void DeformationEncoder::encode(const double* u_m, std::size_t n, std::uint64_t server_step,
                                std::int64_t server_time_ns, neurosim_Deformation& out) {
  if (n != 3 * vertex_count_)
    throw std::invalid_argument("Deformation " + mesh_id_ + ": " + std::to_string(n) +
                                " components, expected 3 x " + std::to_string(vertex_count_));
  double max_u2 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(u_m[i]))
      throw std::invalid_argument("Deformation " + mesh_id_ + ": vertex " + std::to_string(i / 3) +
                                  " displacement is not finite");
    // float32 on the wire; half its range so that a delta between two frames and the sum a
    // decoder forms stay finite too.
    if (std::abs(u_m[i]) > kMaxEncodedDisplacementM)
      throw std::invalid_argument("Deformation " + mesh_id_ + ": vertex " + std::to_string(i / 3) +
                                  " displacement is beyond the float32 range of the wire format");
  }
  for (std::size_t v = 0; v < vertex_count_; ++v) {
    const double* p = u_m + 3 * v;
    max_u2 = std::max(max_u2, p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
  }

  const bool full = !opt_.quantize || !have_base_ || force_full_ ||
                    frame_ - base_frame_ >= opt_.full_frame_period;
  set_string(out.mesh_id, mesh_id_, "Deformation.mesh_id");
  out.topology_revision = revision_;
  out.frame = frame_;
  out.full_frame_period = opt_.quantize ? opt_.full_frame_period : 1;
  out.server_step = server_step;
  out.server_time_ns = server_time_ns;
  out.vertex_count = static_cast<std::uint32_t>(vertex_count_);
  out.max_displacement_m = static_cast<float>(std::sqrt(max_u2));

  if (full) {
    out.encoding = neurosim_ENCODING_FULL;
    out.base_frame = frame_;
    assign(out.displacement_m, u_m, n);
    out.delta_q._length = 0;
    out.delta_scale_m = 0;
    std::copy(out.displacement_m._buffer, out.displacement_m._buffer + n, base_.begin());
    base_frame_ = frame_;
    have_base_ = true;
    force_full_ = false;
  } else {
    out.encoding = neurosim_ENCODING_QUANTIZED_DELTA;
    out.base_frame = base_frame_;
    out.displacement_m._length = 0;
    // Scale so the largest delta maps to +-32767; rounding error <= scale / 2 per component.
    double max_d = 0;
    for (std::size_t i = 0; i < n; ++i) max_d = std::max(max_d, std::abs(u_m[i] - base_[i]));
    const double scale = max_d > 0 ? max_d / 32767.0 : 0.0;
    out.delta_scale_m = static_cast<float>(scale);
    reserve(out.delta_q, n);
    out.delta_q._length = static_cast<std::uint32_t>(n);
    // Quantize against the float scale the viewer will use, clamped for float rounding.
    const double s = static_cast<double>(out.delta_scale_m);
    for (std::size_t i = 0; i < n; ++i) {
      const double q = s > 0 ? std::round((u_m[i] - base_[i]) / s) : 0.0;
      out.delta_q._buffer[i] = static_cast<std::int16_t>(std::clamp(q, -32767.0, 32767.0));
    }
  }
  ++frame_;
}

bool DeformationDecoder::decode(const neurosim_Deformation& in, std::vector<float>& u_m) {
  // Bounded even if a hand-made sample lacks the terminating NUL (DDS always writes one).
  const std::string mesh(in.mesh_id, strnlen(in.mesh_id, sizeof in.mesh_id));
  const std::size_t n = 3 * static_cast<std::size_t>(in.vertex_count);
  if (in.encoding == neurosim_ENCODING_FULL) {
    if (in.displacement_m._length != n)
      throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                  ": FULL frame has " + std::to_string(in.displacement_m._length) +
                                  " components, expected " + std::to_string(n));
    // A non-finite displacement would reach the viewer's resampling and every delta after it.
    for (std::size_t i = 0; i < n; ++i) {
      if (!std::isfinite(in.displacement_m._buffer[i]))
        throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                    ": FULL frame displacement of vertex " + std::to_string(i / 3) +
                                    " is not finite");
    }
    base_.assign(in.displacement_m._buffer, in.displacement_m._buffer + n);
    base_frame_ = in.frame;
    have_base_ = true;
    u_m = base_;
    return true;
  }
  if (in.encoding != neurosim_ENCODING_QUANTIZED_DELTA)
    throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                ": unknown encoding " + std::to_string(in.encoding));
  if (in.delta_q._length != n)
    throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                ": delta has " + std::to_string(in.delta_q._length) +
                                " components, expected " + std::to_string(n));
  if (!std::isfinite(in.delta_scale_m) || in.delta_scale_m < 0)
    throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                ": delta_scale_m is not a finite non-negative number");
  if (!have_base_ || base_frame_ != in.base_frame || base_.size() != n) return false;
  u_m.resize(n);
  bool finite = true;
  for (std::size_t i = 0; i < n; ++i) {
    u_m[i] = base_[i] + in.delta_scale_m * static_cast<float>(in.delta_q._buffer[i]);
    finite = finite && std::isfinite(u_m[i]);
  }
  // A finite scale can still overflow float (3e38 x 32767): refused like a non-finite frame.
  if (!finite)
    throw std::invalid_argument("Deformation " + mesh + " frame " + std::to_string(in.frame) +
                                ": delta_scale_m " + std::to_string(in.delta_scale_m) +
                                " makes displacements overflow float");
  return true;
}

}  // namespace neurosim::wire
