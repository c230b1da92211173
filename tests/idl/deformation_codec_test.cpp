// Deformation codec: FULL frames every period, QUANTIZED_DELTA in between, error bound of the
// quantization, late joiner waits for a FULL frame, bad input rejected.
#include "idl/wire/deformation_codec.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace ns = neurosim::wire;

namespace {

std::vector<double> field(std::size_t nv, double amplitude_m, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> d(-amplitude_m, amplitude_m);
  std::vector<double> u(3 * nv);
  for (double& x : u) x = d(rng);
  return u;
}

}  // namespace

TEST(wire_codec, FullEveryPeriodAndDeltaWithinHalfStep) {
  const std::size_t nv = 500;
  ns::DeformationEncoder enc("brain", nv, 1, {/*full_frame_period=*/4, /*quantize=*/true});
  ns::DeformationDecoder dec;
  ns::Sample<neurosim_Deformation> s;
  std::vector<float> out;
  std::vector<double> u = field(nv, 2e-3, 1);
  for (std::uint64_t f = 0; f < 10; ++f) {
    // Drift away from the last FULL frame so deltas are not trivial.
    const std::vector<double> du = field(nv, 1e-4, 100 + f);
    for (std::size_t i = 0; i < u.size(); ++i) u[i] += du[i];
    enc.encode(u.data(), u.size(), 10 * f, static_cast<std::int64_t>(f), *s);
    EXPECT_EQ(s->frame, f);
    EXPECT_EQ(s->vertex_count, nv);
    EXPECT_STREQ(s->mesh_id, "brain");
    const bool full_expected = f % 4 == 0;
    EXPECT_EQ(s->encoding == neurosim_ENCODING_FULL, full_expected) << "frame " << f;
    EXPECT_EQ(s->base_frame, f - f % 4);
    ASSERT_TRUE(dec.decode(*s, out));
    ASSERT_EQ(out.size(), u.size());
    // FULL: float rounding; delta: half a quantization step plus float rounding.
    const double tol = full_expected ? 1e-9 : 0.5 * s->delta_scale_m + 1e-9;
    double max_err = 0, max_u = 0;
    for (std::size_t i = 0; i < u.size(); ++i) max_err = std::max(max_err, std::abs(out[i] - u[i]));
    for (std::size_t v = 0; v < nv; ++v)
      max_u = std::max(max_u, std::hypot(u[3 * v], u[3 * v + 1], u[3 * v + 2]));
    EXPECT_LE(max_err, tol) << "frame " << f;
    EXPECT_NEAR(s->max_displacement_m, max_u, 1e-9);
    if (!full_expected) {
      EXPECT_EQ(s->displacement_m._length, 0u);
    }
  }
}

TEST(wire_codec, LateJoinerWaitsForFullFrame) {
  const std::size_t nv = 10;
  ns::DeformationEncoder enc("m", nv, 1, {3, true});
  ns::Sample<neurosim_Deformation> s;
  std::vector<double> u = field(nv, 1e-3, 2);
  enc.encode(u.data(), u.size(), 0, 0, *s);  // FULL, missed by the late joiner
  ns::DeformationDecoder late;
  std::vector<float> out;
  enc.encode(u.data(), u.size(), 1, 0, *s);
  EXPECT_FALSE(late.decode(*s, out));
  enc.encode(u.data(), u.size(), 2, 0, *s);
  EXPECT_FALSE(late.decode(*s, out));
  enc.encode(u.data(), u.size(), 3, 0, *s);  // period 3: FULL again
  EXPECT_EQ(s->encoding, neurosim_ENCODING_FULL);
  EXPECT_TRUE(late.decode(*s, out));
  enc.force_full_next();
  enc.encode(u.data(), u.size(), 4, 0, *s);
  EXPECT_EQ(s->encoding, neurosim_ENCODING_FULL);
}

TEST(wire_codec, ZeroMotionDeltaIsExact) {
  const std::size_t nv = 4;
  ns::DeformationEncoder enc("m", nv, 1, {10, true});
  ns::DeformationDecoder dec;
  ns::Sample<neurosim_Deformation> s;
  std::vector<float> out;
  const std::vector<double> u = field(nv, 1e-3, 3);
  enc.encode(u.data(), u.size(), 0, 0, *s);
  ASSERT_TRUE(dec.decode(*s, out));
  enc.encode(u.data(), u.size(), 1, 0, *s);
  EXPECT_EQ(s->encoding, neurosim_ENCODING_QUANTIZED_DELTA);
  // Only the float32 rounding of the FULL frame is left to correct.
  EXPECT_LT(s->delta_scale_m, 1e-12f);
  ASSERT_TRUE(dec.decode(*s, out));
  for (std::size_t i = 0; i < u.size(); ++i) EXPECT_NEAR(out[i], u[i], 1e-9);
}

TEST(wire_codec, RejectsBadInput) {
  const std::size_t nv = 4;
  ns::DeformationEncoder enc("brain", nv, 1);
  ns::Sample<neurosim_Deformation> s;
  std::vector<double> u(3 * nv, 0.0);
  EXPECT_THROW(enc.encode(u.data(), u.size() - 1, 0, 0, *s), std::invalid_argument);
  u[7] = std::numeric_limits<double>::quiet_NaN();
  try {
    enc.encode(u.data(), u.size(), 0, 0, *s);
    ADD_FAILURE() << "NaN accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("brain"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ns::DeformationEncoder("m", 4, 1, {0, true}), std::invalid_argument);

  // A FULL frame whose length disagrees with vertex_count.
  ns::DeformationDecoder dec;
  std::vector<float> out;
  ns::Sample<neurosim_Deformation> bad;
  bad->vertex_count = 5;
  bad->encoding = neurosim_ENCODING_FULL;
  ns::assign(bad->displacement_m, std::vector<float>(14, 0.f));
  EXPECT_THROW(dec.decode(*bad, out), std::invalid_argument);
}

// Frames that decode to non-finite displacements are refused, and a refused FULL frame leaves
// the base as it was (the property fuzz/deformation_codec_fuzz.cpp checks on every frame).
TEST(wire_codec, RejectsFramesThatDecodeToNonFiniteDisplacements) {
  ns::DeformationDecoder dec;
  std::vector<float> out;
  ns::Sample<neurosim_Deformation> full;
  ns::set_string(full->mesh_id, "brain");
  full->vertex_count = 2;
  full->encoding = neurosim_ENCODING_FULL;
  full->frame = 0;
  ns::assign(full->displacement_m, std::vector<float>{1e-3f, 0, 0, 0, 0, 0});
  ASSERT_TRUE(dec.decode(*full, out));

  ns::Sample<neurosim_Deformation> nan_full;
  ns::set_string(nan_full->mesh_id, "brain");
  nan_full->vertex_count = 2;
  nan_full->encoding = neurosim_ENCODING_FULL;
  nan_full->frame = 30;
  ns::assign(nan_full->displacement_m,
             std::vector<float>{0, 0, 0, 0, std::numeric_limits<float>::infinity(), 0});
  const std::string msg = [&] {
    try {
      dec.decode(*nan_full, out);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  }();
  EXPECT_NE(msg.find("brain frame 30"), std::string::npos) << msg;
  EXPECT_NE(msg.find("vertex 1 is not finite"), std::string::npos) << msg;

  // Deltas against frame 0 still decode: the refused frame did not become the base.
  ns::Sample<neurosim_Deformation> delta;
  ns::set_string(delta->mesh_id, "brain");
  delta->vertex_count = 2;
  delta->encoding = neurosim_ENCODING_QUANTIZED_DELTA;
  delta->frame = 1;
  delta->base_frame = 0;
  delta->delta_scale_m = 1e-6f;
  ns::assign(delta->delta_q, std::vector<std::int16_t>{1000, 0, 0, 0, 0, -1000});
  ASSERT_TRUE(dec.decode(*delta, out));
  EXPECT_NEAR(out[0], 2e-3f, 1e-8f);
  EXPECT_NEAR(out[5], -1e-3f, 1e-8f);

  // A finite scale that overflows float once multiplied by the largest step.
  delta->delta_scale_m = 3e38f;
  ns::assign(delta->delta_q, std::vector<std::int16_t>{0, 0, 0, 32767, 0, 0});
  EXPECT_THROW(dec.decode(*delta, out), std::invalid_argument);

  // The encoder refuses a finite double that float32 cannot carry (it would arrive as Inf).
  ns::DeformationEncoder enc("brain", 2, 1);
  std::vector<double> u(6, 0.0);
  u[4] = 1e39;
  ns::Sample<neurosim_Deformation> s;
  try {
    enc.encode(u.data(), u.size(), 0, 0, *s);
    ADD_FAILURE() << "1e39 m encoded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("vertex 1 displacement is beyond the float32 range"),
              std::string::npos)
        << e.what();
  }
}

// Sequence helpers: reuse of buffers, no leaks (checked under ASan/valgrind).
TEST(wire_codec, SequenceHelpersReuseBuffers) {
  ns::Sample<neurosim_Deformation> s;
  ns::assign(s->displacement_m, std::vector<float>(100, 1.f));
  const float* p = s->displacement_m._buffer;
  EXPECT_EQ(s->displacement_m._length, 100u);
  EXPECT_TRUE(s->displacement_m._release);
  ns::assign(s->displacement_m, std::vector<double>(50, 2.0));  // converts double → float
  EXPECT_EQ(s->displacement_m._buffer, p);                     // no reallocation
  EXPECT_EQ(s->displacement_m._length, 50u);
  EXPECT_EQ(s->displacement_m._buffer[49], 2.f);
  ns::assign(s->displacement_m, std::vector<float>(1000, 3.f));
  EXPECT_EQ(ns::to_vector(s->displacement_m), std::vector<float>(1000, 3.f));
  ns::Sample<neurosim_Deformation> moved(std::move(s));
  EXPECT_EQ(s->displacement_m._buffer, nullptr);
  EXPECT_EQ(moved->displacement_m._length, 1000u);
}
