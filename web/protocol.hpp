// The bridge → page protocol over one WebSocket (web/README.md "Protocol"). Text messages are
// JSON objects with a "type" ("topology", "status", "stations", "refused"). Binary messages
// start with a little-endian header whose first byte is the kind:
//
//   kind 1, mesh geometry (one per mesh, right after the "topology" text message):
//      0 u8 kind = 1        1 u8 0               2 u16 mesh index        4 u32 vertex count n
//      8 u32 triangle count t                    12 u32 topology generation
//     16 f32 rest positions [3n] (x0 y0 z0 x1 ..., scene frame, unit m)
//     16 + 12n u32 surface triangles [3t] (0-based vertex ids, outward)
//   kind 2, deformation frame (the server's Deformation codec, forwarded as it came):
//      0 u8 kind = 2        1 u8 encoding (0 FULL, 1 QUANTIZED_DELTA)    2 u16 mesh index
//      4 u32 vertex count n 8 u32 topology generation                    12 u32 0
//     16 u64 frame         24 u64 base frame (DELTA: the FULL frame it adds to)
//     32 i64 server time of the step, unit ns (Unix epoch)
//     40 f32 delta scale, unit m per step      44 f32 max |u| over the vertices, unit m
//     48 FULL: f32 u [3n] (unit m); DELTA: i16 q [3n] with u = u(base frame) + scale * q
//
// A frame is meant for the topology of its generation: the page drops frames of another one.
#pragma once

#include "idl/wire/types.hpp"

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::web {

inline constexpr std::uint8_t kKindMeshGeometry = 1;
inline constexpr std::uint8_t kKindDeformationFrame = 2;
inline constexpr std::size_t kGeometryHeaderBytes = 16;
inline constexpr std::size_t kFrameHeaderBytes = 48;
inline constexpr std::uint8_t kEncodingFull = 0;
inline constexpr std::uint8_t kEncodingDelta = 1;

// One WebSocket message, immutable once built and shared by every client it goes to.
struct Message {
  bool binary = false;
  std::string bytes;
};
using MessagePtr = std::shared_ptr<const Message>;

// A deformation frame as the clients get it.
struct Frame {
  Message message;  // kind 2
  std::uint16_t mesh_index = 0;
  std::uint32_t generation = 0;  // topology generation the frame belongs to
  bool full = true;
  std::uint64_t full_serial = 0;      // bridge serial of the FULL frame needed: its own if FULL
  std::shared_ptr<const Frame> base;  // DELTA: that FULL frame (null for FULL)
  std::int64_t server_time_ns = 0;    // unit ns (Unix epoch)
};
using FramePtr = std::shared_ptr<const Frame>;

// What a client needs before any frame: the "topology" text message, then one geometry message
// per mesh (in mesh index order).
struct Topology {
  std::uint32_t generation = 0;
  std::size_t meshes = 0;
  std::vector<MessagePtr> messages;
};
using TopologyPtr = std::shared_ptr<const Topology>;

// Kind 1. rest_m: 3 per vertex (unit m); triangles: 3 vertex ids each, checked by the caller.
Message geometry_message(std::uint16_t mesh_index, std::uint32_t generation,
                         const std::vector<float>& rest_m,
                         const std::vector<std::uint32_t>& triangles);

// Kind 2 from a Deformation sample whose sizes the caller has checked (3 * vertex_count
// components of the encoding's sequence).
Message frame_message(const neurosim_Deformation& d, std::uint16_t mesh_index,
                      std::uint32_t generation);

// A text message holding json_text.
MessagePtr text_message(std::string json_text);

// Header fields of a kind 2 message (tests, benchmark). Throws std::invalid_argument when bytes
// is not a well-formed frame message.
struct FrameHeader {
  std::uint8_t encoding = 0;
  std::uint16_t mesh_index = 0;
  std::uint32_t vertex_count = 0;
  std::uint32_t generation = 0;
  std::uint64_t frame = 0;
  std::uint64_t base_frame = 0;
  std::int64_t server_time_ns = 0;
  float delta_scale_m = 0;
  float max_displacement_m = 0;
};
FrameHeader parse_frame_header(const char* bytes, std::size_t size);

}  // namespace neurosim::web
