#include "haptic_client/loop.hpp"

#include "common/clock.hpp"
#include "common/thread_sched.hpp"

#include <Eigen/Geometry>

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <stdexcept>

namespace neurosim::haptic {

using common::monotonic_ns;
using common::realtime_ns;

HapticLoop::HapticLoop(const LoopConfig& config, Device& device, Link* link, Recorder* recorder)
    : cfg_(config), device_(device), link_(link), recorder_(recorder), fm_(config.force) {
  if (!cfg_.workspace_origin_m.allFinite())
    throw std::invalid_argument("haptic loop: workspace origin is not finite");
  const double n = cfg_.workspace_up.norm();
  if (!std::isfinite(n) || n == 0)
    throw std::invalid_argument(
        "haptic loop: workspace up direction must be a finite non-zero vector");
  r_ = Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), cfg_.workspace_up / n)
           .toRotationMatrix();
  trace_.reserve(cfg_.trace_capacity);
  sent_time_ns_.assign(kSentPoses, 0);
}

ForceTraceSummary HapticLoop::force_trace() const {
  ForceTraceSummary f;
  f.contact_ticks = contact_ticks_;
  f.max_force_n = max_force_;
  f.mean_contact_force_n =
      contact_ticks_ > 0 ? contact_force_sum_ / static_cast<double>(contact_ticks_) : 0;
  f.models_seen = models_seen_;
  f.foreign_models = foreign_models_;
  f.rigid_contact_ticks = rigid_ticks_;
  f.max_wall_force_n = max_wall_force_;
  f.max_wall_penetration_m = max_wall_penetration_;
  return f;
}

std::uint64_t HapticLoop::recorder_dropped() const { return recorder_ ? recorder_->dropped() : 0; }

bool HapticLoop::answers_own_pose(const ContactModelData& m) const {
  const std::uint64_t q = m.tool_sequence;
  return q >= 1 && q <= seq_ && seq_ - q < kSentPoses &&
         sent_time_ns_[q % kSentPoses] == m.reference_time_ns;
}

void HapticLoop::tick(std::int64_t now_ns, double t_s, double period_s, double lateness_s) {
  const DeviceReading r = device_.read(t_s);
  ToolSample ts;
  ts.sequence_number = ++seq_;
  ts.source_time_ns = now_ns;
  ts.buttons = r.buttons;
  if (device_.scene_frame()) {
    ts.position_m = r.position_m;
    ts.velocity_m_per_s = r.velocity_m_per_s;
    ts.orientation = r.orientation;
  } else {
    const double s = cfg_.force.workspace_scale;
    ts.position_m = cfg_.workspace_origin_m + s * (r_ * r.position_m);
    ts.velocity_m_per_s = s * (r_ * r.velocity_m_per_s);
    const Eigen::Quaterniond q =
        Eigen::Quaterniond(r_) *
        Eigen::Quaterniond(r.orientation[0], r.orientation[1], r.orientation[2], r.orientation[3]);
    ts.orientation = {q.w(), q.x(), q.y(), q.z()};
  }
  bool alive = true;
  const ContactModelData* nm = nullptr;
  if (link_ != nullptr) {
    // The device position, also when a rigid plane holds the proxy back: the server projects it
    // onto its own obstacles again (sending the proxy would hide how deep the hand pushes).
    link_->publish(ts);
    sent_time_ns_[ts.sequence_number % kSentPoses] = ts.source_time_ns;
    if (link_->take_model(model_buf_)) {
      // Only a model answering a pose of this loop: under a station id another participant
      // also writes, the server may answer that writer's poses (never rendered here).
      if (answers_own_pose(model_buf_)) nm = &model_buf_;
      else ++foreign_models_;
    }
    alive = link_->server_alive();
  }
  ForceInput in;
  in.now_ns = now_ns;
  in.position_m = ts.position_m;
  in.velocity_m_per_s = ts.velocity_m_per_s;
  in.new_model = nm;
  in.server_alive = alive;
  const ForceOutput out = fm_.step(in);
  device_.command(device_.scene_frame() ? out.force_n
                                        : Eigen::Vector3d(r_.transpose() * out.force_n));

  const double step = (out.force_n - last_force_).norm();
  const double fmag = out.force_n.norm();
  max_force_ = std::max(max_force_, fmag);
  if (out.in_contact) {
    ++contact_ticks_;
    contact_force_sum_ += fmag;
  }
  if (out.rigid_contact) {
    ++rigid_ticks_;
    max_wall_force_ = std::max(max_wall_force_, out.wall_force_n.norm());
    max_wall_penetration_ = std::max(max_wall_penetration_, (out.proxy_m - ts.position_m).norm());
  }
  if (out.model_sequence != last_model_seq_) {
    last_model_seq_ = out.model_sequence;
    ++models_seen_;
  }
  last_force_ = out.force_n;
  metrics_.add_tick(period_s, lateness_s, out.has_model ? out.model_age_s : -1, step);

  if (recorder_ != nullptr) {
    RecordSample rs;
    rs.time_s = t_s;
    rs.position_m = ts.position_m;
    rs.orientation = ts.orientation;
    rs.velocity_m_per_s = ts.velocity_m_per_s;
    rs.buttons = ts.buttons;
    rs.force_n = out.force_n;
    rs.contact_model_sequence = out.model_sequence;
    rs.tool_sequence = ts.sequence_number;
    rs.in_contact = out.in_contact;
    recorder_->push(rs);
  }
  if (trace_.size() < cfg_.trace_capacity) {
    TickTrace tt;
    tt.now_ns = now_ns;
    tt.t_s = t_s;
    tt.position_m = ts.position_m;
    tt.force_n = out.force_n;
    tt.model_age_s = out.has_model ? out.model_age_s : -1;
    tt.gain = out.gain;
    tt.in_contact = out.in_contact;
    tt.server_alive = alive;
    tt.model_sequence = out.model_sequence;
    tt.rigid_contact = out.rigid_contact;
    tt.proxy_m = out.proxy_m;
    tt.wall_force_n = out.wall_force_n;
    tt.active_planes = out.active_planes;
    trace_.push_back(tt);
  }
  last_force_norm_.store(out.force_n.norm(), std::memory_order_release);
  ticks_done_.store(seq_, std::memory_order_release);
}

void HapticLoop::run_simulated(std::size_t ticks, std::int64_t start_ns) {
  const double T = cfg_.force.period_s;
  const auto T_ns = static_cast<std::int64_t>(std::llround(T * 1e9));
  for (std::size_t k = 0; k < ticks; ++k) {
    const double t = static_cast<double>(k) * T;
    if (device_.finished(t)) break;
    tick(start_ns + static_cast<std::int64_t>(k) * T_ns, t, k == 0 ? -1 : T, 0);
  }
}

RealtimeInfo HapticLoop::run_realtime(double duration_s, const std::atomic<bool>* stop) {
  RealtimeInfo info;
  int old_policy = 0;
  sched_param old_param{};
  pthread_getschedparam(pthread_self(), &old_policy, &old_param);
  {
    const std::string line = common::apply_to_this_thread(
        {"loop", cfg_.thread_name, cfg_.realtime_priority ? cfg_.rt_priority : 0, cfg_.cpus});
    if (cfg_.sched_log != nullptr) cfg_.sched_log(line.c_str());
  }
  if (cfg_.realtime_priority) {
    int policy = 0;
    sched_param p{};
    pthread_getschedparam(pthread_self(), &policy, &p);
    const int rc = policy == SCHED_FIFO ? 0 : EPERM;
    if (rc == 0) {
      info.sched_fifo = true;
      mlockall(MCL_CURRENT);  // fewer page faults in the loop (MCL_FUTURE could break allocation)
    } else {
      info.warning = std::string("SCHED_FIFO not permitted (") + std::strerror(rc) +
                     "): running at normal priority; expect late ticks under load";
      if (cfg_.warn != nullptr) cfg_.warn(info.warning.c_str());
    }
  }
  const double T = cfg_.force.period_s;
  const auto T_ns = static_cast<std::int64_t>(std::llround(T * 1e9));
  if (!(cfg_.spin_us >= 0) || cfg_.spin_us * 1e3 >= static_cast<double>(T_ns))
    throw std::invalid_argument("haptic loop: spin_us " + std::to_string(cfg_.spin_us) +
                                " µs must be in [0, period)");
  const auto spin_ns = static_cast<std::int64_t>(std::llround(cfg_.spin_us * 1e3));
  // Normal-priority threads get 50 µs of timer slack by default; the loop wants its wake-up on
  // time (SCHED_FIFO threads have none anyway). No system call in the loop but the clock.
  const int old_slack = prctl(PR_GET_TIMERSLACK, 0UL, 0UL, 0UL, 0UL);
  prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  std::int64_t deadline = monotonic_ns() + T_ns;
  std::int64_t prev_start = -1;
  for (std::uint64_t k = 0;; ++k) {
    const double t = static_cast<double>(k) * T;
    if (duration_s > 0 && t >= duration_s) break;
    if (stop != nullptr && stop->load(std::memory_order_relaxed)) break;
    if (device_.finished(t)) break;
    common::sleep_until_ns(deadline - spin_ns);
    std::int64_t start = monotonic_ns();
    while (start < deadline) start = monotonic_ns();  // the last spin_ns: vDSO clock reads only
    const double period = prev_start < 0 ? -1 : 1e-9 * static_cast<double>(start - prev_start);
    prev_start = start;
    tick(realtime_ns(), t, period, 1e-9 * static_cast<double>(start - deadline));
    deadline += T_ns;
    // Far behind (machine stalled): re-anchor instead of a burst of catch-up ticks.
    if (monotonic_ns() - deadline > 100 * T_ns) {
      deadline = monotonic_ns() + T_ns;
      ++info.resyncs;
    }
  }
  device_.command(Eigen::Vector3d::Zero());
  if (old_slack > 0) prctl(PR_SET_TIMERSLACK, static_cast<unsigned long>(old_slack), 0UL, 0UL, 0UL);
  if (info.sched_fifo) pthread_setschedparam(pthread_self(), old_policy, &old_param);
  return info;
}

recording::Header session_header(const LoopConfig& config, const Device& device,
                                 const std::string& station_id, const std::string& tool_id,
                                 const std::string& scene_name, const std::string& scene_file,
                                 const std::string& label, std::int64_t start_time_unix_ns) {
  recording::Header h;
  h.set_scene_name(scene_name);
  h.set_scene_file(scene_file);
  h.set_station_id(station_id);
  h.set_tool_id(tool_id);
  auto* d = h.mutable_device();
  d->set_kind(device.kind());
  d->set_model(device.model());
  d->set_max_force_n(config.force.max_force_n);
  d->set_max_stiffness_n_per_m(config.force.max_stiffness_n_per_m);
  d->set_force_scale(config.force.force_scale);
  d->set_workspace_scale(config.force.workspace_scale);
  h.set_start_time_unix_ns(start_time_unix_ns);
  h.set_sample_rate_hz(1.0 / config.force.period_s);
  h.set_label(label);
  h.set_software_version("neurosim 0.1.0");
  return h;
}

}  // namespace neurosim::haptic
