// A session for fault tests: the real neurosim-server in its own process (topic prefix of its
// own), real haptic stations (DdsLink + HapticLoop) in the test process holding a scripted tool
// in the cube, and a SimStatus probe.
#pragma once

#include "common/clock.hpp"
#include "common/process_stats.hpp"
#include "haptic_client/dds_link.hpp"
#include "haptic_client/loop.hpp"
#include "idl/wire/dds.hpp"
#include "server/service/service_test_util.hpp"
#include "test_support.hpp"

#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <functional>
#include <memory>
#include <thread>

namespace neurosim::fault_testing {

namespace fs = std::filesystem;
namespace nh = neurosim::haptic;
namespace wire = neurosim::wire;
using Eigen::Vector3d;
using neurosim::common::Clock;
using neurosim::common::seconds_since;
using neurosim::service::testing::ChildProcess;


inline void sleep_s(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

// The cube's right face (x = 0.1 m), outward normal +x.
inline const Vector3d kFaceNormal(1, 0, 0);

struct Session {
  explicit Session(const std::string& tag)
      : dir(neurosim::testing::temp_dir("fault_" + tag)),
        prefix(tag + std::to_string(::getpid()) + "_") {}
  ~Session() { fs::remove_all(dir); }
  // extra: further server options (e.g. {"--station-idle-timeout", "60"}).
  std::unique_ptr<ChildProcess> start_server(const std::string& log_name,
                                             const std::vector<std::string>& extra = {}) {
    std::vector<std::string> args{"--scene",
                                  (neurosim::testing::source_dir() / "scenes/cube_cylinder.scene").string(),
                                  "--topic-prefix", prefix, "--duration", "120"};
    args.insert(args.end(), extra.begin(), extra.end());
    return std::make_unique<ChildProcess>(neurosim::testing::bin_dir() / "neurosim-server", args,
                                          dir / log_name);
  }
  fs::path dir;
  std::string prefix;
};

// One haptic station: the real client holding its tool `depth_m` into the cube's right face at
// height y (m), or moving it by a script, with a trace of every tick.
class Station {
 public:
  Station(const Session& s, const std::string& id, double y, double depth_m, double seconds)
      : Station(s, id, y, std::make_unique<nh::ConstantScript>(Vector3d(0, 0, -depth_m)),
                seconds) {}
  // Any scripted motion (device frame: the face at z = 0, -z into the cube).
  Station(const Session& s, const std::string& id, double y, std::unique_ptr<nh::Script> script,
          double seconds)
      : config_(make_config(y, seconds)),
        link_(options(s, id)),
        device_(std::move(script)),
        loop_(config_, device_, &link_, nullptr) {
    thread_ = std::thread([this, seconds] { loop_.run_realtime(seconds, &stop_); });
  }
  ~Station() { join(); }
  void join() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
  }
  bool wait_for_server(double timeout_s) { return link_.wait_for_server(timeout_s); }
  double force() const { return loop_.last_force_norm(); }
  std::uint64_t ticks() const { return loop_.ticks(); }
  const std::vector<nh::TickTrace>& trace() const { return loop_.trace(); }
  const nh::LoopConfig& config() const { return config_; }
  nh::DdsLinkCounters counters() const { return link_.counters(); }
  // Force-model counters (read after join()).
  const nh::ForceModelCounters& model_counters() const { return loop_.force_model().counters(); }
  // Waits until the force is at least f (N); false after timeout_s.
  bool wait_force_at_least(double f, double timeout_s) const {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      if (force() >= f) return true;
      sleep_s(0.01);
    }
    return false;
  }
  // The server answers this station (within 60 s) and its force reaches f (N, within 30 s); the
  // failure names the force and carries the server's log.
  ::testing::AssertionResult pressing(double f, const ChildProcess& server) {
    if (!wait_for_server(60))
      return ::testing::AssertionFailure() << "no server within 60 s\n" << server.log();
    if (!wait_force_at_least(f, 30))
      return ::testing::AssertionFailure() << "force " << force() << " N, not " << f << " N\n"
                                           << server.log();
    return ::testing::AssertionSuccess();
  }
  // Largest |F(k) - F(k-1)| per nominal period over the trace, unit N.
  double max_force_step() const {
    const auto& tr = trace();
    double m = 0;
    for (std::size_t i = 1; i < tr.size(); ++i) {
      const double periods =
          std::max(1.0, 1e-6 * static_cast<double>(tr[i].now_ns - tr[i - 1].now_ns));
      m = std::max(m, (tr[i].force_n - tr[i - 1].force_n).norm() / periods);
    }
    return m;
  }

 private:
  static nh::DdsLinkOptions options(const Session& s, const std::string& id) {
    nh::DdsLinkOptions o;
    o.station_id = id;
    o.topic_prefix = s.prefix;
    o.publisher_rt_priority = o.receiver_rt_priority = 0;
    return o;
  }
  static nh::LoopConfig make_config(double y, double seconds) {
    nh::LoopConfig c;
    c.workspace_origin_m = Vector3d(0.1, y, 0.05);
    c.workspace_up = kFaceNormal;
    c.force.ramp_in_s = 0.2;
    c.realtime_priority = false;
    c.trace_capacity = static_cast<std::size_t>(seconds * 1000) + 1000;
    return c;
  }
  nh::LoopConfig config_;
  nh::DdsLink link_;
  nh::ScriptDevice device_;
  nh::HapticLoop loop_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

// Time from the reference time of the newest model before tick `from` to the last tick that
// still pushed (ms): how long the force outlived the server's last answer.
inline double force_outlived_ms(const std::vector<nh::TickTrace>& tr, std::size_t from) {
  std::uint64_t last_seq = 0;
  std::int64_t last_ref = 0;
  // The whole trace: a server starved by load may send nothing for the 300 ticks before the kill
  // (a window that short once left no model in it, and the epoch as the reference).
  for (std::size_t i = 0; i < tr.size(); ++i) {
    if (tr[i].model_sequence > last_seq && tr[i].force_n.norm() > 0) {
      last_seq = tr[i].model_sequence;
      last_ref = tr[i].now_ns - static_cast<std::int64_t>(std::llround(tr[i].model_age_s * 1e9));
    }
    if (i > from && tr[i].force_n.norm() == 0)
      return last_seq > 0 ? 1e-6 * static_cast<double>(tr[i - 1].now_ns - last_ref) : -1;
  }
  return -1;
}

// The newest SimStatus of the server under `prefix`, taken from its own participant.
class StatusProbe {
 public:
  explicit StatusProbe(const std::string& prefix)
      : topic_(pp_, wire::topic_name<neurosim_SimStatus>(prefix)), reader_(pp_, topic_) {}
  // Waits for a status satisfying pred (the newest kept in `last`).
  bool wait_for(const std::function<bool(const neurosim_SimStatus&)>& pred, double timeout_s) {
    const auto t0 = Clock::now();
    while (seconds_since(t0) < timeout_s) {
      for (const auto& rx : reader_.take()) {
        if (!rx.valid()) continue;
        text = neurosim::service::testing::StatusWatcher::describe(rx.data);
        steps = rx.data.steps;
        p99_us = rx.data.step_time_p99_us;
        refused = rx.data.stations_refused;
        if (pred(rx.data)) return true;
      }
      sleep_s(0.05);
    }
    return false;
  }
  std::string text;
  std::uint64_t steps{0}, refused{0};
  double p99_us{0};

 private:
  wire::Participant pp_;
  wire::Topic<neurosim_SimStatus> topic_;
  wire::Reader<neurosim_SimStatus> reader_;
};

// A server, its SimStatus probe and station "a" at height y (m) holding its tool depth_m into
// the cube's face for `seconds`. Tests take it apart: auto& [s, server, status, a] = t;
struct OneStation {
  OneStation(const std::string& tag, double y, double depth_m, double seconds)
      : s(tag), server(s.start_server("server.log")), status(s.prefix), a(s, "a", y, depth_m, seconds) {}
  Session s;
  std::unique_ptr<ChildProcess> server;
  StatusProbe status;
  Station a;
};


}  // namespace neurosim::fault_testing
