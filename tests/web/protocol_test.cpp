// The protocol's binary messages: header layout and size checks.
#include "web/protocol.hpp"

#include "test_support.hpp"

#include <gtest/gtest.h>

#include <cstring>

namespace web = neurosim::web;
namespace wire = neurosim::wire;
namespace nt = neurosim::testing;

TEST(Protocol, FullFrameLayout) {
  wire::Sample<neurosim_Deformation> d;
  wire::set_string(d->mesh_id, "m");
  d->encoding = neurosim_ENCODING_FULL;
  d->vertex_count = 2;
  d->frame = 1ULL << 40;
  d->server_time_ns = -5;
  d->max_displacement_m = 0.5F;
  const float u[6] = {1, 2, 3, 4, 5, 6};
  wire::assign(d->displacement_m, u, 6);
  const web::Message m = web::frame_message(*d, 3, 9);
  ASSERT_TRUE(m.binary);
  ASSERT_EQ(m.bytes.size(), web::kFrameHeaderBytes + 24);
  const web::FrameHeader h = web::parse_frame_header(m.bytes.data(), m.bytes.size());
  EXPECT_EQ(h.encoding, web::kEncodingFull);
  EXPECT_EQ(h.mesh_index, 3);
  EXPECT_EQ(h.generation, 9U);
  EXPECT_EQ(h.frame, 1ULL << 40);
  EXPECT_EQ(h.base_frame, 1ULL << 40);  // a FULL frame is its own base
  EXPECT_EQ(h.server_time_ns, -5);
  EXPECT_FLOAT_EQ(h.max_displacement_m, 0.5F);
  float u5 = 0;
  std::memcpy(&u5, &m.bytes[web::kFrameHeaderBytes + 20], 4);
  EXPECT_EQ(u5, 6.0F);
}

TEST(Protocol, HeaderParsingRefusesWrongSizesAndKinds) {
  const std::string tiny(10, '\0');
  EXPECT_NE(nt::message_of([&] {
              web::parse_frame_header(tiny.data(), tiny.size());
            }).find("not a deformation frame message (10 bytes)"),
            std::string::npos);
  wire::Sample<neurosim_Deformation> d;
  d->encoding = neurosim_ENCODING_QUANTIZED_DELTA;
  d->vertex_count = 3;
  const std::int16_t q[9] = {};
  wire::assign(d->delta_q, q, 9);
  std::string bytes = web::frame_message(*d, 0, 1).bytes;
  EXPECT_EQ(bytes.size(), web::kFrameHeaderBytes + 18);
  bytes.pop_back();
  EXPECT_NE(nt::message_of([&] {
              web::parse_frame_header(bytes.data(), bytes.size());
            }).find("does not match its header (encoding 1, 3 vertices)"),
            std::string::npos);
}
