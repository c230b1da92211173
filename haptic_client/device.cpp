#include "haptic_client/device.hpp"

#include "idl/wire/recording_io.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>

namespace neurosim::haptic {

namespace {

constexpr double kPi = 3.14159265358979323846;

// 0 → 1 with zero slope at both ends, u in [0, 1].
double smooth(double u) {
  u = std::clamp(u, 0.0, 1.0);
  return 0.5 - 0.5 * std::cos(kPi * u);
}

// Press: 4 s cycle, from 4 mm above the surface to 4 mm into it and back.
class PressScript : public Script {
 public:
  std::string name() const override { return "press"; }
  Eigen::Vector3d position(double t) const override {
    const double c = std::fmod(std::max(t, 0.0), 4.0);
    double s = 0;
    if (c < 1.5)
      s = smooth(c / 1.5);
    else if (c < 2.0)
      s = 1;
    else if (c < 3.5)
      s = 1 - smooth((c - 2.0) / 1.5);
    return {0, 0, 0.004 - 0.008 * s};
  }
};

// Hold: the press's descent (1.5 s, from 4 mm above the surface to 4 mm into it), held there
// for hold_s, the press's withdrawal (1.5 s), then 4 mm above (a viscoelastic tissue's force
// relaxes during the hold).
class HoldScript : public Script {
 public:
  explicit HoldScript(double hold_s, std::string name) : hold_s_(hold_s), name_(std::move(name)) {}
  std::string name() const override { return name_; }
  Eigen::Vector3d position(double t) const override {
    t = std::max(t, 0.0);
    double s = 0;
    if (t < 1.5)
      s = smooth(t / 1.5);
    else if (t < 1.5 + hold_s_)
      s = 1;
    else
      s = 1 - smooth((t - 1.5 - hold_s_) / 1.5);
    return {0, 0, 0.004 - 0.008 * s};
  }

 private:
  double hold_s_;
  std::string name_;
};

// Stroke: descend to 2 mm depth in 1 s, then slide ±10 mm along x (3 s period).
class StrokeScript : public Script {
 public:
  std::string name() const override { return "stroke"; }
  Eigen::Vector3d position(double t) const override {
    t = std::max(t, 0.0);
    const double z = 0.004 - 0.006 * smooth(t);
    const double x = t < 1 ? 0 : 0.01 * std::sin(2 * kPi * (t - 1) / 3.0) * smooth(t - 1);
    return {x, 0, z};
  }
};

// Circle: descend to 2 mm depth in 1 s, then a 10 mm radius circle every 2 s.
class CircleScript : public Script {
 public:
  std::string name() const override { return "circle"; }
  Eigen::Vector3d position(double t) const override {
    t = std::max(t, 0.0);
    const double z = 0.004 - 0.006 * smooth(t);
    const double r = 0.01 * smooth(t - 1);  // grow the radius smoothly from the centre
    const double a = 2 * kPi * std::max(t - 1, 0.0) / 2.0;
    return {r * std::cos(a), r * std::sin(a), z};
  }
};

// Retract: start 4 mm into the tissue, hold 0.5 s, withdraw to 10 mm above within 1 s.
class RetractScript : public Script {
 public:
  std::string name() const override { return "retract"; }
  Eigen::Vector3d position(double t) const override {
    return {0, 0, -0.004 + 0.014 * smooth((t - 0.5) / 1.0)};
  }
};

// Approach: the surgical approach through a craniotomy (the paper's Figure 16). Device frame:
// origin on the brain surface at the opening's centre, +z the opening's axis out of the head
// (neurosim-haptic --at-opening). From 32 mm beside the opening and 25 mm out, down onto the
// skull, along the bone to the opening, over its rim, down onto the cerebellum (4 mm past first
// touch), 1 mm aside (pushing it towards the rim), out again and back to the start outside the
// head; each leg eased (zero speed at every waypoint); repeats every 12 s. Set for
// brain_skull.scene: along the slide the tip (radius 2 mm) is commanded about 1 mm behind the
// bone's outer table (3-8 mm above the brain surface there), so the proxy holds it on the bone
// with about 1 N; it presses the cerebellum on a surface node of the brain mesh 5 mm from the
// opening's centre (the node-based tissue contact of a 7 mm mesh: between nodes a 2 mm tip
// slides through without force, so it pushes at a node).
class ApproachScript : public Script {
 public:
  std::string name() const override { return "approach"; }
  Eigen::Vector3d position(double t) const override {
    struct Waypoint {
      double t_s;
      double x_mm, y_mm, z_mm;
    };
    static constexpr Waypoint kPath[] = {
        {0.0, -32, 0, 25},      // outside the head, beside the opening
        {0.5, -32, 0, 25},      // hold
        {2.0, -32, 0, 3.5},     // down onto the bone
        {3.3, -24, 0, 7.5},     // along the bone ...
        {4.5, -17, 0, 8.5},     // ... to the rim
        {5.5, -5, 0.5, 8.5},    // over the rim, above the cerebellum
        {7.0, -5, 0.5, -2},     // down onto the cerebellum
        {8.0, -6, 0.5, -2},     // aside, towards the rim
        {8.7, -6, 0.5, -2},     // hold
        {10.0, -6, 0.5, 25},    // out of the opening
        {11.5, -32, 0, 25},     // back beside it, outside the head
        {12.0, -32, 0, 25},     // hold; then again
    };
    constexpr std::size_t n = sizeof(kPath) / sizeof(kPath[0]);
    t = std::fmod(std::max(t, 0.0), kPath[n - 1].t_s);
    const auto at = [](const Waypoint& w) { return Eigen::Vector3d(w.x_mm, w.y_mm, w.z_mm); };
    Eigen::Vector3d p_mm = at(kPath[n - 1]);
    for (std::size_t i = 1; i < n; ++i) {
      if (t < kPath[i].t_s) {
        const double u = smooth((t - kPath[i - 1].t_s) / (kPath[i].t_s - kPath[i - 1].t_s));
        p_mm = at(kPath[i - 1]) + u * (at(kPath[i]) - at(kPath[i - 1]));
        break;
      }
    }
    return 1e-3 * p_mm;
  }
};

}  // namespace

Eigen::Vector3d Script::velocity(double t_s) const {
  constexpr double h = 1e-6;
  return (position(t_s + h) - position(t_s - h)) / (2 * h);
}

const std::vector<std::string>& script_names() {
  static const std::vector<std::string> names{"press", "stroke", "circle", "retract",
                                              "approach", "hold"};
  return names;
}

namespace {

// script_names() joined by ", ", for messages.
std::string script_list() {
  std::string list;
  for (const auto& n : script_names()) list += (list.empty() ? "" : ", ") + n;
  return list;
}

}  // namespace

std::unique_ptr<Script> make_script(const std::string& name) {
  if (name == "press") return std::make_unique<PressScript>();
  if (name == "stroke") return std::make_unique<StrokeScript>();
  if (name == "circle") return std::make_unique<CircleScript>();
  if (name == "retract") return std::make_unique<RetractScript>();
  if (name == "approach") return std::make_unique<ApproachScript>();
  // hold (10 s) or hold:S, the hold time in seconds.
  if (name == "hold") return std::make_unique<HoldScript>(10.0, name);
  if (name.rfind("hold:", 0) == 0) {
    const std::string arg = name.substr(5);
    char* end = nullptr;
    const double s = std::strtod(arg.c_str(), &end);
    if (arg.empty() || end != arg.c_str() + arg.size() || !std::isfinite(s) || s < 0 || s > 86400)
      throw std::invalid_argument("script '" + name + "': the hold time must be a number of seconds in [0, 86400]");
    return std::make_unique<HoldScript>(s, name);
  }
  throw std::invalid_argument("unknown script '" + name + "' (known: " + script_list() + ")");
}

ScriptDevice::ScriptDevice(std::unique_ptr<Script> script) : script_(std::move(script)) {
  if (!script_) throw std::invalid_argument("ScriptDevice: no script");
}

DeviceReading ScriptDevice::read(double t_s) {
  DeviceReading r;
  r.position_m = script_->position(t_s);
  r.velocity_m_per_s = script_->velocity(t_s);
  r.buttons = r.position_m.z() < 0 ? 1u : 0u;  // button 0 "pressing" while below the surface
  return r;
}

HandDevice::HandDevice(std::unique_ptr<Script> target, const HandParams& params)
    : target_(std::move(target)), p_(params) {
  if (!target_) throw std::invalid_argument("HandDevice: no target script");
  if (!(p_.mass_kg > 0) || !(p_.stiffness_n_per_m >= 0) || !(p_.damping_n_s_per_m >= 0) ||
      p_.substeps < 1)
    throw std::invalid_argument(
        "HandDevice: mass must be > 0, stiffness and damping >= 0, substeps >= 1");
  x_ = target_->position(0);
  v_ = target_->velocity(0);
}

void HandDevice::set_state(const Eigen::Vector3d& x_m, const Eigen::Vector3d& v_m_per_s) {
  x_ = x_m;
  v_ = v_m_per_s;
}

DeviceReading HandDevice::read(double t_s) {
  if (!started_) {
    t_ = t_s;
    started_ = true;
  }
  // Semi-implicit Euler over [t_, t_s]; the commanded force is held (zero-order hold).
  const double dt_total = t_s - t_;
  if (dt_total > 0) {
    const double h = dt_total / p_.substeps;
    for (int i = 0; i < p_.substeps; ++i) {
      const double ti = t_ + (i + 1) * h;
      const Eigen::Vector3d grip = p_.stiffness_n_per_m * (target_->position(ti) - x_) +
                                   p_.damping_n_s_per_m * (target_->velocity(ti) - v_);
      v_ += h * (grip + force_) / p_.mass_kg;
      x_ += h * v_;
    }
    t_ = t_s;
  }
  DeviceReading r;
  r.position_m = x_;
  r.velocity_m_per_s = v_;
  r.buttons = x_.z() < 0 ? 1u : 0u;
  return r;
}

ReplayDevice::ReplayDevice(const std::string& file) : file_(file) {
  wire::RecordingReader reader(file);
  header_ = reader.header();
  recording::Sample s;
  while (reader.next(s)) {
    DeviceReading r;
    r.position_m = {s.position_m().x(), s.position_m().y(), s.position_m().z()};
    r.orientation = {s.orientation().w(), s.orientation().x(), s.orientation().y(),
                     s.orientation().z()};
    if (!s.has_orientation()) r.orientation = {1, 0, 0, 0};
    r.velocity_m_per_s = {s.velocity_m_per_s().x(), s.velocity_m_per_s().y(),
                          s.velocity_m_per_s().z()};
    r.buttons = s.buttons();
    samples_.push_back(r);
    times_.push_back(s.time_s());
  }
  if (samples_.empty()) throw std::runtime_error(file + ": recording has no samples to replay");
}

double ReplayDevice::max_force_n() const {
  const double f = header_.device().max_force_n();
  return f > 0 ? f : 3.3;
}

DeviceReading ReplayDevice::read(double t_s) {
  // Newest sample at or before t (half a microsecond of slack for accumulated rounding).
  while (i_ + 1 < times_.size() && times_[i_ + 1] <= t_s + 5e-7) ++i_;
  return samples_[i_];
}

bool ReplayDevice::finished(double t_s) const { return t_s > times_.back() + 5e-7; }

std::unique_ptr<Device> make_omni_device(const std::string& name);  // omni_device.cpp / below

#ifndef NEUROSIM_HAVE_OPENHAPTICS
bool omni_supported() { return false; }
std::unique_ptr<Device> make_omni_device(const std::string& name) {
  throw std::invalid_argument(
      "device 'omni" + (name.empty() ? std::string() : ":" + name) +
      "': not built in: this neurosim-haptic was built without the OpenHaptics HD API (HD/hd.h "
      "and libHD were not found at configure time). Use script:NAME, hand:SCRIPT or replay:FILE.");
}
#endif

std::unique_ptr<Device> make_device(const std::string& spec) {
  const auto colon = spec.find(':');
  const std::string kind = spec.substr(0, colon);
  const std::string arg = colon == std::string::npos ? std::string() : spec.substr(colon + 1);
  if (kind == "omni") return make_omni_device(arg);
  if (kind == "script" && !arg.empty()) return std::make_unique<ScriptDevice>(make_script(arg));
  if (kind == "hand" && !arg.empty()) return std::make_unique<HandDevice>(make_script(arg));
  if (kind == "replay" && !arg.empty()) return std::make_unique<ReplayDevice>(arg);
  throw std::invalid_argument("bad device '" + spec +
                              "' (expected omni[:NAME], replay:FILE, script:NAME or hand:SCRIPT; "
                              "scripts: " + script_list() + ")");
}

}  // namespace neurosim::haptic
