// Haptic devices: scripted motions, a simulated hand holding the stylus,
// replay of a recording, and the Phantom Omni (only where OpenHaptics is found at build time).
//
// Device frame: metres around the device centre; the loop maps it to the scene with the
// workspace origin, "up" direction and scale. Scripts put the tissue surface at z = 0 with its
// outward normal +z (pressing = moving towards -z). A replay already holds scene coordinates
// (scene_frame() true) and is passed through unchanged.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "recording.pb.h"

namespace neurosim::haptic {

struct DeviceReading {
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();        // unit m
  Eigen::Vector4d orientation = Eigen::Vector4d(1, 0, 0, 0);   // quaternion (w, x, y, z)
  Eigen::Vector3d velocity_m_per_s = Eigen::Vector3d::Zero();  // unit m/s
  std::uint32_t buttons = 0;
};

class Device {
 public:
  virtual ~Device() = default;
  // "script:press", "simulated_hand:press", "replay:FILE", "omni:NAME" (recording DeviceSpec.kind).
  virtual std::string kind() const = 0;
  virtual std::string model() const = 0;
  virtual double max_force_n() const { return 3.3; }
  // Reading at time t since the loop started (unit s, non-decreasing). Called once per tick.
  virtual DeviceReading read(double t_s) = 0;
  // Force to render until the next tick (device axes, unit N).
  virtual void command(const Eigen::Vector3d& force_n) = 0;
  // Positions already in the scene frame (replay).
  virtual bool scene_frame() const { return false; }
  // No more data (a replay that reached its end).
  virtual bool finished(double /*t_s*/) const { return false; }
};

// A motion of the device (or the hand's target): position at time t, device frame.
class Script {
 public:
  virtual ~Script() = default;
  virtual std::string name() const = 0;
  virtual Eigen::Vector3d position(double t_s) const = 0;
  // Central difference of position (scripts are smooth).
  Eigen::Vector3d velocity(double t_s) const;
};

// Built-in scripts: press, stroke, circle, retract, approach, hold (hold:S: the press held S s).
// Throws std::invalid_argument listing them.
std::unique_ptr<Script> make_script(const std::string& name);
const std::vector<std::string>& script_names();

// A fixed point (tests).
class ConstantScript : public Script {
 public:
  explicit ConstantScript(const Eigen::Vector3d& p) : p_(p) {}
  std::string name() const override { return "constant"; }
  Eigen::Vector3d position(double) const override { return p_; }

 private:
  Eigen::Vector3d p_;
};

// The stylus follows the script exactly (forces are recorded, not felt).
class ScriptDevice : public Device {
 public:
  explicit ScriptDevice(std::unique_ptr<Script> script);
  std::string kind() const override { return "script:" + script_->name(); }
  std::string model() const override { return "scripted motion"; }
  DeviceReading read(double t_s) override;
  void command(const Eigen::Vector3d& force_n) override { last_force_ = force_n; }
  const Eigen::Vector3d& last_force() const { return last_force_; }

 private:
  std::unique_ptr<Script> script_;
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
};

// A hand holding the stylus: the stylus (mass m) is pulled to the script's point by a spring
// and damper (the grip) while the commanded force acts on it, so force changes motion.
struct HandParams {
  double mass_kg = 0.15;           // stylus + fingers, unit kg
  double stiffness_n_per_m = 300;  // grip spring, unit N/m
  double damping_n_s_per_m = 3;    // grip damper, unit N s/m
  int substeps = 10;               // integration steps per read() interval
};

class HandDevice : public Device {
 public:
  HandDevice(std::unique_ptr<Script> target, const HandParams& params = {});
  // Start the stylus somewhere else than the target (tests).
  void set_state(const Eigen::Vector3d& x_m, const Eigen::Vector3d& v_m_per_s);
  std::string kind() const override { return "simulated_hand:" + target_->name(); }
  std::string model() const override { return "simulated hand (mass-spring-damper)"; }
  DeviceReading read(double t_s) override;
  void command(const Eigen::Vector3d& force_n) override { force_ = force_n; }
  const HandParams& params() const { return p_; }
  const Eigen::Vector3d& position() const { return x_; }
  const Eigen::Vector3d& velocity() const { return v_; }
  Eigen::Vector3d target(double t_s) const { return target_->position(t_s); }

 private:
  std::unique_ptr<Script> target_;
  HandParams p_;
  Eigen::Vector3d x_, v_;
  Eigen::Vector3d force_ = Eigen::Vector3d::Zero();  // held over the interval (zero-order hold)
  double t_ = 0;
  bool started_ = false;
};

// Plays back a recording's ToolState samples (scene frame): at time t the newest sample with
// time_s <= t. Loaded fully at construction (no file I/O in the loop).
class ReplayDevice : public Device {
 public:
  explicit ReplayDevice(const std::string& file);
  std::string kind() const override { return "replay:" + file_; }
  std::string model() const override { return header_.device().model(); }
  double max_force_n() const override;
  DeviceReading read(double t_s) override;
  void command(const Eigen::Vector3d&) override {}
  bool scene_frame() const override { return true; }
  bool finished(double t_s) const override;
  const recording::Header& header() const { return header_; }
  std::size_t size() const { return samples_.size(); }

 private:
  std::string file_;
  recording::Header header_;
  std::vector<DeviceReading> samples_;
  std::vector<double> times_;
  std::size_t i_ = 0;
};

// True when this build has the OpenHaptics HD API (omni devices).
bool omni_supported();

// SPEC: omni[:NAME] | replay:FILE | script:NAME | hand:SCRIPT. Throws std::invalid_argument
// with the accepted forms (and, for omni without OpenHaptics, says it is not built in).
std::unique_ptr<Device> make_device(const std::string& spec);

}  // namespace neurosim::haptic
