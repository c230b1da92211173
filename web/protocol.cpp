#include "web/protocol.hpp"

#include <cstring>
#include <stdexcept>

// The protocol is little-endian; arrays are copied as they are in memory, which is right only on
// a little-endian host (every machine neurosim runs on).
static_assert(__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__, "web/protocol.cpp assumes little-endian");

namespace neurosim::web {

namespace {

template <class T>
void put(std::string& out, std::size_t offset, T v) {
  std::memcpy(&out[offset], &v, sizeof v);
}

template <class T>
T get(const char* bytes, std::size_t offset) {
  T v;
  std::memcpy(&v, bytes + offset, sizeof v);
  return v;
}

}  // namespace

Message geometry_message(std::uint16_t mesh_index, std::uint32_t generation,
                         const std::vector<float>& rest_m,
                         const std::vector<std::uint32_t>& triangles) {
  Message m;
  m.binary = true;
  const std::size_t n = rest_m.size() / 3, t = triangles.size() / 3;
  m.bytes.assign(kGeometryHeaderBytes + 4 * rest_m.size() + 4 * triangles.size(), '\0');
  put<std::uint8_t>(m.bytes, 0, kKindMeshGeometry);
  put<std::uint16_t>(m.bytes, 2, mesh_index);
  put<std::uint32_t>(m.bytes, 4, static_cast<std::uint32_t>(n));
  put<std::uint32_t>(m.bytes, 8, static_cast<std::uint32_t>(t));
  put<std::uint32_t>(m.bytes, 12, generation);
  if (!rest_m.empty())
    std::memcpy(&m.bytes[kGeometryHeaderBytes], rest_m.data(), 4 * rest_m.size());
  if (!triangles.empty())
    std::memcpy(&m.bytes[kGeometryHeaderBytes + 4 * rest_m.size()], triangles.data(),
                4 * triangles.size());
  return m;
}

Message frame_message(const neurosim_Deformation& d, std::uint16_t mesh_index,
                      std::uint32_t generation) {
  const bool full = d.encoding == neurosim_ENCODING_FULL;
  const std::size_t components = 3 * static_cast<std::size_t>(d.vertex_count);
  const std::size_t payload = full ? 4 * components : 2 * components;
  Message m;
  m.binary = true;
  m.bytes.assign(kFrameHeaderBytes + payload, '\0');
  put<std::uint8_t>(m.bytes, 0, kKindDeformationFrame);
  put<std::uint8_t>(m.bytes, 1, full ? kEncodingFull : kEncodingDelta);
  put<std::uint16_t>(m.bytes, 2, mesh_index);
  put<std::uint32_t>(m.bytes, 4, d.vertex_count);
  put<std::uint32_t>(m.bytes, 8, generation);
  put<std::uint64_t>(m.bytes, 16, d.frame);
  put<std::uint64_t>(m.bytes, 24, full ? d.frame : d.base_frame);
  put<std::int64_t>(m.bytes, 32, d.server_time_ns);
  put<float>(m.bytes, 40, full ? 0.0F : d.delta_scale_m);
  put<float>(m.bytes, 44, d.max_displacement_m);
  const void* src = full ? static_cast<const void*>(d.displacement_m._buffer)
                         : static_cast<const void*>(d.delta_q._buffer);
  if (payload > 0) std::memcpy(&m.bytes[kFrameHeaderBytes], src, payload);
  return m;
}

MessagePtr text_message(std::string json_text) {
  auto m = std::make_shared<Message>();
  m->binary = false;
  m->bytes = std::move(json_text);
  return m;
}

FrameHeader parse_frame_header(const char* bytes, std::size_t size) {
  if (size < kFrameHeaderBytes || static_cast<std::uint8_t>(bytes[0]) != kKindDeformationFrame)
    throw std::invalid_argument("not a deformation frame message (" + std::to_string(size) +
                                " bytes)");
  FrameHeader h;
  h.encoding = get<std::uint8_t>(bytes, 1);
  h.mesh_index = get<std::uint16_t>(bytes, 2);
  h.vertex_count = get<std::uint32_t>(bytes, 4);
  h.generation = get<std::uint32_t>(bytes, 8);
  h.frame = get<std::uint64_t>(bytes, 16);
  h.base_frame = get<std::uint64_t>(bytes, 24);
  h.server_time_ns = get<std::int64_t>(bytes, 32);
  h.delta_scale_m = get<float>(bytes, 40);
  h.max_displacement_m = get<float>(bytes, 44);
  const std::size_t per = h.encoding == kEncodingFull ? 4 : 2;
  if (h.encoding > kEncodingDelta ||
      size != kFrameHeaderBytes + per * 3 * static_cast<std::size_t>(h.vertex_count))
    throw std::invalid_argument("deformation frame message of " + std::to_string(size) +
                                " bytes does not match its header (encoding " +
                                std::to_string(h.encoding) + ", " + std::to_string(h.vertex_count) +
                                " vertices)");
  return h;
}

}  // namespace neurosim::web
