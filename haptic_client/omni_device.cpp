// Phantom Omni / Touch through the OpenHaptics HD API (compiled only where HD/hd.h and libHD
// are found; see CMakeLists.txt). NOT compiled or tested on the development machines (no
// OpenHaptics there): written against the HD API reference, check on hardware first.
//
// The HD servo thread (1 kHz, owned by OpenHaptics) exchanges the newest reading and force
// with the neurosim loop through lock-free slots; the device's own force clamping and ramping
// are enabled too, on top of ForceModel's clamp and ramp-in.
#include "haptic_client/device.hpp"
#include "common/triple_buffer.hpp"

#include <HD/hd.h>

#include <Eigen/Geometry>

#include <stdexcept>
#include <string>

namespace neurosim::haptic {

namespace {

std::string hd_error_text(const HDErrorInfo& e, const char* what) {
  return std::string("omni: ") + what + ": " + hdGetErrorString(e.errorCode) + " (code " +
         std::to_string(e.errorCode) + ", internal " + std::to_string(e.internalErrorCode) + ")";
}

class OmniDevice : public Device {
 public:
  explicit OmniDevice(const std::string& name) : name_(name) {
    hhd_ = hdInitDevice(name.empty() ? HD_DEFAULT_DEVICE : name.c_str());
    HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e))
      throw std::runtime_error(hd_error_text(e, ("cannot open device '" + name + "'").c_str()));
    hdMakeCurrentDevice(hhd_);
    hdEnable(HD_FORCE_OUTPUT);
    hdEnable(HD_MAX_FORCE_CLAMPING);  // the device's own clamp, on top of ours
    hdEnable(HD_FORCE_RAMPING);       // the device's own ramp-in at start
    HDdouble max_force = 0;
    hdGetDoublev(HD_NOMINAL_MAX_FORCE, &max_force);
    if (max_force > 0) max_force_ = max_force;
    const char* model = reinterpret_cast<const char*>(hdGetString(HD_DEVICE_MODEL_TYPE));
    if (model != nullptr) model_ = model;
    servo_ = hdScheduleAsynchronous(&OmniDevice::servo, this, HD_DEFAULT_SCHEDULER_PRIORITY);
    hdStartScheduler();
    e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {
      hdUnschedule(servo_);
      hdDisableDevice(hhd_);
      throw std::runtime_error(hd_error_text(e, "cannot start the servo scheduler"));
    }
  }
  ~OmniDevice() override {
    hdStopScheduler();
    hdUnschedule(servo_);
    hdDisableDevice(hhd_);
  }

  std::string kind() const override {
    return "omni" + (name_.empty() ? std::string() : ":" + name_);
  }
  std::string model() const override { return model_; }
  double max_force_n() const override { return max_force_; }
  DeviceReading read(double) override {
    reading_slot_.take(last_reading_);  // keep the previous reading if no new one
    return last_reading_;
  }
  void command(const Eigen::Vector3d& force_n) override { force_slot_.publish(force_n); }

 private:
  static HDCallbackCode HDCALLBACK servo(void* self_ptr) {
    auto* self = static_cast<OmniDevice*>(self_ptr);
    hdBeginFrame(self->hhd_);
    HDdouble pos[3], vel[3], m[16];
    HDint buttons = 0;
    hdGetDoublev(HD_CURRENT_POSITION, pos);  // unit mm
    hdGetDoublev(HD_CURRENT_VELOCITY, vel);  // unit mm/s
    hdGetDoublev(HD_CURRENT_TRANSFORM, m);   // column-major 4x4
    hdGetIntegerv(HD_CURRENT_BUTTONS, &buttons);
    DeviceReading r;
    r.position_m = Eigen::Vector3d(pos[0], pos[1], pos[2]) * 1e-3;
    r.velocity_m_per_s = Eigen::Vector3d(vel[0], vel[1], vel[2]) * 1e-3;
    Eigen::Matrix3d rot;
    rot << m[0], m[4], m[8], m[1], m[5], m[9], m[2], m[6], m[10];
    const Eigen::Quaterniond q(rot);
    r.orientation = {q.w(), q.x(), q.y(), q.z()};
    r.buttons = static_cast<std::uint32_t>(buttons);
    self->reading_slot_.publish(r);
    self->force_slot_.take(self->servo_force_);
    HDdouble f[3] = {self->servo_force_.x(), self->servo_force_.y(), self->servo_force_.z()};
    hdSetDoublev(HD_CURRENT_FORCE, f);
    hdEndFrame(self->hhd_);
    // Errors raised in the frame (e.g. the device's own force clamp) are consumed here so they
    // do not pile up; the servo keeps running.
    (void)hdGetError();
    return HD_CALLBACK_CONTINUE;
  }

  std::string name_;
  std::string model_ = "Phantom Omni";
  double max_force_ = 3.3;
  HHD hhd_ = HD_INVALID_HANDLE;
  HDSchedulerHandle servo_ = 0;
  common::TripleBuffer<DeviceReading> reading_slot_;
  common::TripleBuffer<Eigen::Vector3d> force_slot_;
  DeviceReading last_reading_;
  Eigen::Vector3d servo_force_ = Eigen::Vector3d::Zero();
};

}  // namespace

bool omni_supported() { return true; }

std::unique_ptr<Device> make_omni_device(const std::string& name) {
  return std::make_unique<OmniDevice>(name);
}

}  // namespace neurosim::haptic
