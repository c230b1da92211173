// The haptic client's local force model (docs/ARCHITECTURE.md "haptic_client"):
// extrapolation of the newest server ContactModel, F = f0 + K (x - x0) with f0 relaxing in time
// for viscoelastic tissue (the model's relaxing parts), blended on a new model,
// with passivity-limited stiffness and damping, device clamp, per-tick step bound, ramp-in,
// model watchdog, server-gone and NaN handling; rigid obstacles (the model's constraint planes)
// rendered as a wall on a proxy (proxy.hpp) and added to the tissue force.
//
// Pure and allocation-free: no DDS, no clocks (time is an argument), no heap after construction,
// so every safety rule is unit-testable in simulated time.
#pragma once

#include "haptic_client/proxy.hpp"

#include <Eigen/Core>

#include <array>
#include <cstddef>
#include <cstdint>

namespace neurosim::haptic {

// The part of a model's f0 relaxing with one time constant while the tool is held
// (ContactModel.relaxing_forces: viscoelastic tissue).
struct RelaxingForce {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // unit N
  double tau_s = 0;                                   // relaxation time, > 0, unit s
};
inline constexpr std::size_t kMaxRelaxingForces = 8;  // the IDL's bound

// One ContactModel as the loop sees it (copied out of the DDS sample; SI units).
struct ContactModelData {
  std::uint64_t tool_sequence = 0;     // ToolState.sequence_number it answers
  std::int64_t reference_time_ns = 0;  // time the model refers to (the answered ToolState's
                                       // source time), same clock as ForceInput::now_ns, unit ns
  Eigen::Vector3d x0_m = Eigen::Vector3d::Zero();       // reference tool tip, scene frame, unit m
  Eigen::Vector3d f0_n = Eigen::Vector3d::Zero();       // force on the tool at x0, unit N
  Eigen::Matrix3d k_n_per_m = Eigen::Matrix3d::Zero();  // K = dF/dx at x0 (instantaneous), N/m
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();     // out of the tissue, unit vector
  bool in_contact = false;
  double validity_radius_m = 0;  // extrapolate within this distance of x0 (0: no limit), unit m
  std::uint64_t server_step = 0;
  // Rigid obstacles near the tool (ContactModel.rigid_planes), rigid: valid until replaced by
  // the next model's planes (no validity radius), empty when none is near.
  RigidPlaneSet rigid_planes;
  // Viscoelastic tissue: held at x0, the force at reference_time_ns + s is
  // f0 + sum_i (exp(-s / tau_i) - 1) relaxing[i].force_n (none: f0 holds).
  std::array<RelaxingForce, kMaxRelaxingForces> relaxing{};
  std::size_t num_relaxing = 0;
};

struct ForceModelConfig {
  double period_s = 1e-3;              // loop period T, unit s
  double max_force_n = 3.3;            // device clamp |F| (Phantom Omni peak), unit N
  double max_stiffness_n_per_m = 700;  // device-side stiffness limit (Omni usable), unit N/m
  double max_damping_n_s_per_m = 5;    // device-side usable damping (Omni), unit N s/m
  // Virtual damping along the normal while in contact; < 0: automatic, passivity_margin times
  // the minimum K T / 2 (K < 2b/T, Colgate & Schenkel), capped at max_damping_n_s_per_m.
  double damping_n_s_per_m = -1;
  double passivity_margin = 2;  // b >= margin * K T / 2
  // Limit stiffness so K < 2b/T holds with the margin. Off only to demonstrate instability.
  bool enforce_passivity = true;
  double force_scale = 1;          // device force = scale * simulated force (scene haptics factor)
  double workspace_scale = 1;      // simulated displacement = scale * device displacement
  double blend_s = 0.005;          // a new model takes over within this time of its arrival, unit s
  double ramp_in_s = 0.5;          // force gain 0 → 1 at start / after an outage, unit s
  double model_timeout_s = 0.05;   // model older than this → force fades out, unit s
  double fade_s = 0.02;            // fade-out time, unit s
  // Wall stiffness of rigid planes (the proxy spring), device side; < 0: the passivity-limited
  // device stiffness (max_stiffness_n_per_m, lowered to 2b/(T margin) when enforced). Above
  // that limit is refused. Unit N/m.
  double wall_stiffness_n_per_m = -1;
  double max_force_step_n = 0.25;  // bound on |F(k) - F(k-1)| per nominal period (a late tick
                                   // may move as far as the ticks it replaced); NaN input zeroes
                                   // at once, unit N
  // Throws std::invalid_argument naming the field if something is non-finite or out of range.
  void validate() const;
};

struct ForceInput {
  std::int64_t now_ns = 0;                                     // loop time, unit ns
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();        // tool tip, scene frame, unit m
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();  // scene frame, unit m/s
  const ContactModelData* new_model = nullptr;  // a model that arrived since last tick
  bool server_alive = true;                     // SimStatus liveliness
};

struct ForceOutput {
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();  // device force, scene axes, unit N
  bool in_contact = false;                            // model in use says in contact
  bool has_model = false;
  double model_age_s = 0;            // age of the model in use, unit s
  double gain = 0;                   // ramp/watchdog gain in [0, 1]
  std::uint64_t model_sequence = 0;  // tool_sequence of the model in use
  // Rigid obstacles: the proxy (closest free point to the device under the model's planes),
  // whether the device is behind a plane, how many planes hold the proxy (0..3), and the wall
  // force (spring + damper, device side, after the gain, before the clamp of the total).
  bool rigid_contact = false;
  Eigen::Vector3d proxy_m = Eigen::Vector3d::Zero();  // scene frame, unit m
  std::size_t active_planes = 0;
  std::size_t rigid_planes = 0;                            // planes in the model in use
  Eigen::Vector3d wall_force_n = Eigen::Vector3d::Zero();  // unit N
};

struct ForceModelCounters {
  std::uint64_t nan_inputs = 0;   // non-finite position or velocity (force zeroed)
  std::uint64_t nan_models = 0;   // non-finite ContactModel (rejected)
  std::uint64_t nan_outputs = 0;  // non-finite force computed (zeroed; should stay 0)
  std::uint64_t models_accepted = 0;
  std::uint64_t server_lost = 0;        // transitions to server gone
  std::uint64_t timeouts = 0;           // transitions to a stale model
  std::uint64_t stiffness_limited = 0;  // models scaled down (f0 and K) to the passive limit
  std::uint64_t planes_dropped = 0;     // rigid planes refused (non-finite, non-unit normal)
  std::uint64_t planes_infeasible = 0;  // ticks whose planes left no free point
};

class ForceModel {
 public:
  explicit ForceModel(const ForceModelConfig& config);

  ForceOutput step(const ForceInput& in);
  // Forget models and output, ramp in again (e.g. reconnect).
  void reset();

  const ForceModelConfig& config() const { return cfg_; }
  const ForceModelCounters& counters() const { return counters_; }
  // Stiffness limit in the scene frame (N/m) and damping b (N s/m, device side) in use.
  double scene_stiffness_limit() const { return k_limit_scene_; }
  double damping() const { return damping_; }
  // Stiffness of the rigid wall in the scene frame (N/m), <= scene_stiffness_limit().
  double wall_stiffness_scene() const { return k_wall_scene_; }

  // Simulated force of one model at x, age_s after its reference time (scene frame, before
  // scaling, gain, damping, clamp): f0 relaxed by its relaxing parts over age_s, plus K (x - x0)
  // with x - x0 limited to the validity radius; zero out of contact or when the result would
  // pull the tool into the tissue (unilateral).
  static Eigen::Vector3d extrapolate(const ContactModelData& m, const Eigen::Vector3d& x,
                                     double age_s = 0);

 private:
  bool accept(const ContactModelData& m, const Eigen::Vector3d& x, std::int64_t now_ns);
  // Wall spring of a plane set at x, simulated (scene) force k_wall (proxy - x), unit N.
  Eigen::Vector3d wall_spring(const RigidPlaneSet& planes, const Eigen::Vector3d& x,
                              Proxy& proxy) const;

  ForceModelConfig cfg_;
  double k_limit_scene_ = 0;
  double damping_ = 0;
  double k_wall_scene_ = 0;
  Proxy proxy_;
  ContactModelData current_{};
  bool has_current_ = false;
  // Blend: rendered = extrapolate(current) + offset; the offset (the force jump at a model
  // change) shrinks linearly to zero within blend_s of the latest change.
  Eigen::Vector3d blend_offset_ = Eigen::Vector3d::Zero();  // unit N (simulated)
  double blend_rate_ = 0;                                   // unit N/s
  std::int64_t last_now_ns_ = 0;
  bool have_last_now_ = false;
  double gain_ = 0;
  bool stale_ = false;
  bool server_gone_ = false;
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
  ForceModelCounters counters_{};
};

}  // namespace neurosim::haptic
