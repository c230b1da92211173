// The server-side proxy (god-object) of one tool against the rigid obstacles: the tip the
// physics uses is the newest tip projected onto the free side of the obstacle's constraint
// planes, which are taken around the last accepted free tip, so a fast tool that jumps through
// the bone shell between two steps is held where it came from, and the tissue behind the bone is
// never pushed through it. One per station, in the interaction State (the step's "pose" phase),
// so the live server and a replay hold the tool alike; allocation-free after construction.
#pragma once

#include "server/interaction/rigid_obstacle.hpp"
#include "server/interaction/simulation.hpp"

namespace neurosim::interaction {

struct ToolProxyOptions {
  // Surface points within this distance of the tool's surface become planes, and the proxy
  // moves at most this far per step (beyond it the planes say nothing), unit m. Above the
  // fastest tool's travel per step (2 m/s x 1 ms = 2 mm; the server takes the larger of this and
  // 1.5 x its tools' fastest travel per step). Its cost: rigid_bench (bench/RESULTS.md).
  double reach_m{0.003};
  // A device that travelled further than reach_m since the last step (the server missed steps, a
  // fast jump) is followed in one step up to this distance: the planes are then taken within its
  // travel, so free motion never lags; beyond it the proxy moves this far per step, unit m.
  double max_reach_m{0.03};
  int projection_iterations{64};  // Dykstra sweeps over the planes
  double tolerance_m{1e-9};       // accepted residual penetration of the projected tip, unit m
};

class ToolProxy {
 public:
  ToolProxy(const RigidObstacle& obstacle, const ToolProxyOptions& options = {});

  // pose: in, the newest pose (the device); out, the pose the physics steps (tip on the free side
  // of every plane; axis and tool unchanged). planes: the constraint planes, penetration of the
  // newest pose behind each.
  void constrain(const ToolShape& shape, ToolPose& pose, ObstaclePlanes& planes);
  // What the proxy remembers between steps (constrain reads and writes it): a step that fails
  // after constrain puts it back, so the failure leaves the station's proxy as it was.
  struct Memory {
    bool has_free{false};
    mesh::Vec3 free_tip_m{mesh::Vec3::Zero()};
    bool has_last_raw{false};
    mesh::Vec3 last_raw_m{mesh::Vec3::Zero()};  // the device's tip at the last call
  };
  Memory memory() const { return {has_free_, free_tip_m_, has_last_raw_, last_raw_m_}; }
  void restore(const Memory& k) {
    has_free_ = k.has_free;
    free_tip_m_ = k.free_tip_m;
    has_last_raw_ = k.has_last_raw;
    last_raw_m_ = k.last_raw_m;
  }
  // Forget the free tip (the station left): the next pose starts afresh.
  void reset() { restore(Memory{}); }
  bool has_free() const { return has_free_; }
  const mesh::Vec3& free_tip_m() const { return free_tip_m_; }

 private:
  const RigidObstacle* obstacle_;
  ToolProxyOptions options_;
  RigidObstacle::Scratch scratch_;
  std::array<mesh::Vec3, kMaxObstaclePlanes> dykstra_{};
  bool has_free_{false};
  mesh::Vec3 free_tip_m_{mesh::Vec3::Zero()};
  bool has_last_raw_{false};
  mesh::Vec3 last_raw_m_{mesh::Vec3::Zero()};  // the device's tip at the last call
};

}  // namespace neurosim::interaction
