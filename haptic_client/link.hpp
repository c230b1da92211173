// What the loop sends and receives each tick, independent of DDS (tests use in-process fakes;
// DdsLink in dds_link.hpp is the real one).
#pragma once

#include "haptic_client/force_model.hpp"

#include <Eigen/Core>

#include <cstdint>

namespace neurosim::haptic {

// One ToolState as the loop publishes it (scene frame, SI units).
struct ToolSample {
  std::uint64_t sequence_number = 0;  // starts at 1, +1 per tick
  std::int64_t source_time_ns = 0;    // when the pose was sampled, unit ns (loop clock)
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Vector4d orientation = Eigen::Vector4d(1, 0, 0, 0);  // (w, x, y, z)
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();
  std::uint32_t buttons = 0;
};

class Link {
 public:
  virtual ~Link() = default;
  // Called from the loop thread every tick: must not block.
  virtual void publish(const ToolSample& s) = 0;
  // Newest ContactModel for this station since the last call, without blocking.
  virtual bool take_model(ContactModelData& out) = 0;
  // False once the server is known gone (SimStatus liveliness lost).
  virtual bool server_alive() = 0;
};

}  // namespace neurosim::haptic
