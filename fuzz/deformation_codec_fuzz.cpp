// Fuzz target: the Deformation codec (idl/wire/deformation_codec.cpp). Even first byte: a
// sequence of hand-made frames (either encoding, any vertex count, lengths, scale, float bits,
// an unterminated mesh id) into one DeformationDecoder: it may refuse a frame with
// std::invalid_argument, and what it decodes is 3 x vertex_count finite values. Odd first
// byte: displacement fields made from the input, encoded and decoded frame after frame: every
// frame decodes, FULL frames to float rounding, deltas to half a quantization step.
#include "fuzz/fuzz_target.hpp"
#include "idl/wire/deformation_codec.hpp"

#include <cfloat>
#include <cmath>
#include <stdexcept>
#include <vector>

namespace {

using neurosim::fuzz::Bytes;
using neurosim::fuzz::require;
namespace wire = neurosim::wire;

void decode_frames(Bytes& in) {
  wire::DeformationDecoder decoder;
  std::vector<float> u;
  for (int frame = 0; frame < 16 && in.left() > 0; ++frame) {
    wire::Sample<neurosim_Deformation> d;
    const std::uint8_t flags = in.u8();
    if (flags & 1) {
      std::memset(d->mesh_id, 'm', sizeof d->mesh_id);  // no terminating NUL
    } else {
      wire::set_string(d->mesh_id, "fuzz");
    }
    // Only the two enumerators: any other value of the C enum is undefined behaviour in C++,
    // and Cyclone DDS refuses a sample whose enum is out of range before it is delivered.
    d->encoding = static_cast<neurosim_DeformationEncoding>(in.u8() % 2);
    d->vertex_count = (flags & 2) ? in.u32() : in.u8() % 16;
    d->frame = in.u8() % 4;
    d->base_frame = in.u8() % 4;
    d->delta_scale_m = in.take<float>();
    std::vector<float> full(in.u8() % 64);
    for (float& x : full) x = in.take<float>();
    std::vector<std::int16_t> delta(in.u8() % 64);
    for (auto& q : delta) q = in.take<std::int16_t>();
    wire::assign(d->displacement_m, full);
    wire::assign(d->delta_q, delta);
    try {
      if (!decoder.decode(*d, u)) continue;  // a delta without its base: waits
    } catch (const std::invalid_argument&) {
      continue;
    }
    require(u.size() == 3 * static_cast<std::size_t>(d->vertex_count), "3 values per vertex");
    for (float x : u) require(std::isfinite(x), "decoded displacements are finite");
  }
}

void round_trip(Bytes& in) {
  const std::size_t nv = in.u8() % 32 + 1;
  wire::DeformationEncoderOptions options;
  options.full_frame_period = in.u8() % 8 + 1;
  options.quantize = (in.u8() & 1) == 0;
  // Amplitude from 1e-9 m to 1e39 m: beyond float32's range the encoder must refuse.
  const double amplitude_m = std::pow(10.0, static_cast<int>(in.u8() % 49) - 9);
  wire::DeformationEncoder encoder("fuzz", nv, 1, options);
  wire::DeformationDecoder decoder;
  wire::Sample<neurosim_Deformation> d;
  std::vector<double> u(3 * nv);
  std::vector<float> decoded;
  for (int frame = 0; frame < 8 && in.left() > 0; ++frame) {
    for (double& x : u) x = amplitude_m * in.take<std::int16_t>() / 32767.0;
    try {
      encoder.encode(u.data(), u.size(), 0, 0, *d);
    } catch (const std::invalid_argument&) {
      double max_u = 0.0;
      for (double x : u) max_u = std::max(max_u, std::abs(x));
      require(max_u > wire::kMaxEncodedDisplacementM,
              "the encoder refuses only what float cannot carry");
      return;
    }
    require(decoder.decode(*d, decoded), "every frame of an unbroken stream decodes");
    require(decoded.size() == u.size(), "3 values per vertex");
    const double step = d->encoding == neurosim_ENCODING_FULL ? 0.0 : d->delta_scale_m;
    for (std::size_t i = 0; i < u.size(); ++i) {
      // Half a step, and float rounding of the value, the base and the scaled step.
      const double tolerance = 0.5 * step * (1.0 + 1e-3) +
                               4.0 * FLT_EPSILON * (std::abs(u[i]) + 32767.0 * step) + FLT_MIN;
      require(std::abs(decoded[i] - u[i]) <= tolerance, "decoded within half a step");
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Bytes in(data, size);
  if (in.u8() % 2 == 0) {
    decode_frames(in);
  } else {
    round_trip(in);
  }
  return 0;
}
