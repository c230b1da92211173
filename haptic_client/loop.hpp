// The 1 kHz haptic loop: each tick read the device, publish the ToolState,
// take the newest ContactModel without blocking, compute the force (ForceModel), command it,
// record the sample, update the metrics. run_realtime() paces ticks with clock_nanosleep on
// absolute deadlines; run_simulated() calls the same tick with simulated time (tests).
#pragma once

#include "haptic_client/device.hpp"
#include "haptic_client/force_model.hpp"
#include "haptic_client/link.hpp"
#include "haptic_client/metrics.hpp"
#include "haptic_client/recorder.hpp"

#include <Eigen/Core>

#include <atomic>
#include <cstdint>
#include <string>
#include <vector>

namespace neurosim::haptic {

struct LoopConfig {
  ForceModelConfig force;  // force.period_s is the loop period
  // Device → scene: x_scene = origin + workspace_scale * R x_device, R turns device +z into
  // `up` (the scripts' surface normal). Not applied to replays (already scene frame).
  Eigen::Vector3d workspace_origin_m = Eigen::Vector3d::Zero();  // unit m
  Eigen::Vector3d workspace_up = Eigen::Vector3d::UnitZ();
  bool realtime_priority = true;  // try SCHED_FIFO (warn and continue if not permitted)
  int rt_priority = 80;
  std::string thread_name = "nh-loop";  // the loop thread's name while run_realtime() runs
  std::vector<int> cpus;                // its CPU set (empty: any CPU)
  void (*sched_log)(const char* line) = nullptr;  // told once what scheduling was granted
  // The loop sleeps until this long before each deadline, then spins on the clock to it, so a
  // tick starts within a few µs of its deadline instead of the scheduler's wake-up latency
  // (tens of µs, more on a busy machine). 0: sleep to the deadline (battery-powered laptops:
  // spinning costs power). Unit µs, 0 ≤ spin_us < period. Default 0: on the project's 2-core VM
  // a 50 µs spin did not reduce the ticks > 1 ms late (they are late timer deliveries and host
  // preemption, bench/RESULTS.md "Real-time margins"); enable it (--spin-us 50) on bare metal
  // where the scheduler's wake-up latency is the limit.
  double spin_us = 0;
  void (*warn)(const char* message) = nullptr;  // told at once when SCHED_FIFO is refused
  std::size_t trace_capacity = 0;               // ticks kept in trace() (allocated up front)
};

// One tick as seen by tests and the demo's force trace.
struct TickTrace {
  std::int64_t now_ns = 0;
  double t_s = 0;
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();  // scene frame
  Eigen::Vector3d force_n = Eigen::Vector3d::Zero();     // device force, scene axes
  double model_age_s = -1;                               // < 0: no model
  double gain = 0;
  bool in_contact = false;
  bool server_alive = true;
  std::uint64_t model_sequence = 0;
  // Rigid obstacles: the device is behind a plane, the proxy, the wall's share of the force
  // (device side, after the gain, before the clamp of the total), planes holding the proxy.
  bool rigid_contact = false;
  Eigen::Vector3d proxy_m = Eigen::Vector3d::Zero();  // scene frame
  Eigen::Vector3d wall_force_n = Eigen::Vector3d::Zero();
  std::size_t active_planes = 0;
};

// Force trace summary printed at exit (not part of the --summary JSON contract).
struct ForceTraceSummary {
  std::uint64_t contact_ticks = 0;  // ticks whose model said in contact
  double max_force_n = 0;           // largest |F| commanded, unit N
  double mean_contact_force_n = 0;  // mean |F| over contact ticks, unit N
  std::uint64_t models_seen = 0;    // distinct model sequences used
  // Models ignored because they answer no pose this loop sent (their tool_sequence and source
  // time echo are not one of its own: another writer under the same station id, a stale
  // session), never rendered.
  std::uint64_t foreign_models = 0;
  std::uint64_t rigid_contact_ticks = 0;  // ticks with the device behind a rigid plane
  double max_wall_force_n = 0;            // largest |wall force| (before the clamp), unit N
  double max_wall_penetration_m = 0;      // largest |proxy - device|, scene frame, unit m
};

struct RealtimeInfo {
  bool sched_fifo = false;    // SCHED_FIFO was granted
  std::string warning;        // why not, if requested
  std::uint64_t resyncs = 0;  // deadline re-anchored after falling > 100 ms behind
};

class HapticLoop {
 public:
  // link and recorder may be null (no server / no recording). All must outlive the loop.
  HapticLoop(const LoopConfig& config, Device& device, Link* link, Recorder* recorder);

  // One tick at loop time now_ns (model ages use this clock), nominal time t_s since start.
  void tick(std::int64_t now_ns, double t_s, double period_s, double lateness_s);
  // Ticks at simulated times start_ns + k T (no sleeping); stops early when a replay ends.
  void run_simulated(std::size_t ticks, std::int64_t start_ns = 0);
  // Real time for duration_s (<= 0: until stop), or until *stop becomes true / a replay ends.
  RealtimeInfo run_realtime(double duration_s, const std::atomic<bool>* stop = nullptr);

  const ForceModel& force_model() const { return fm_; }
  LoopSummary summary() const { return metrics_.summary(); }
  const std::vector<TickTrace>& trace() const { return trace_; }
  // Safe to call from other threads while run_realtime() runs.
  std::uint64_t ticks() const { return ticks_done_.load(std::memory_order_acquire); }
  double last_force_norm() const { return last_force_norm_.load(std::memory_order_acquire); }
  std::uint64_t recorder_dropped() const;
  const Eigen::Vector3d& last_force() const { return last_force_; }
  ForceTraceSummary force_trace() const;

 private:
  LoopConfig cfg_;
  Device& device_;
  Link* link_;
  Recorder* recorder_;
  ForceModel fm_;
  LoopMetrics metrics_;
  Eigen::Matrix3d r_;  // device → scene rotation
  ContactModelData model_buf_{};
  std::uint64_t seq_ = 0;
  // Source time sent with each of the last kSentPoses sequence numbers (index seq % size): a
  // model is used only when it answers one of them exactly (answers_own_pose).
  static constexpr std::size_t kSentPoses = 4096;  // 4 s at 1 kHz; models older are stale anyway
  std::vector<std::int64_t> sent_time_ns_;
  std::uint64_t foreign_models_ = 0;
  bool answers_own_pose(const ContactModelData& m) const;
  Eigen::Vector3d last_force_ = Eigen::Vector3d::Zero();
  std::vector<TickTrace> trace_;
  std::atomic<std::uint64_t> ticks_done_{0};
  std::uint64_t contact_ticks_ = 0, models_seen_ = 0, last_model_seq_ = 0;
  double max_force_ = 0, contact_force_sum_ = 0;
  std::uint64_t rigid_ticks_ = 0;
  double max_wall_force_ = 0, max_wall_penetration_ = 0;
  std::atomic<double> last_force_norm_{0};
};

// Recording header for a session of this loop (format set by the writer).
recording::Header session_header(const LoopConfig& config, const Device& device,
                                 const std::string& station_id, const std::string& tool_id,
                                 const std::string& scene_name, const std::string& scene_file,
                                 const std::string& label, std::int64_t start_time_unix_ns);

}  // namespace neurosim::haptic
