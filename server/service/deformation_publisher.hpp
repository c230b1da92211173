// Deformation frames for the viewers (docs/ARCHITECTURE.md "Processes and DDS topics"): at the
// viewer rate, only while a reader is matched, the step thread snapshots the last step's forces
// (Simulation::snapshot, no solve) and hands them to the field thread, which solves every mesh's
// displacement field (Simulation::displacements from the snapshot), encodes it (FULL frame every
// full_frame_period frames and right after a new viewer matched, QUANTIZED_DELTA between) and
// writes it. A tick that finds the field thread still busy is skipped, never waited for. Once per
// status period the frame's fields are also measured for the largest strain (SimStatus).
#pragma once

#include "idl/wire/deformation_codec.hpp"
#include "idl/wire/dds.hpp"
#include "server/interaction/simulation.hpp"

#include <Eigen/Core>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace neurosim::service {

struct DeformationCounters {
  std::atomic<std::uint64_t> frames{0};             // all meshes
  std::atomic<std::uint64_t> full_field_solves{0};  // displacement fields computed (per mesh)
  std::atomic<std::uint64_t> skipped{0};            // ticks skipped: the field thread was busy
};

class DeformationPublisher {
 public:
  // Creates the Deformation writer on `pp` (topic name with `topic_prefix`) and one encoder per
  // mesh of `sim`.
  DeformationPublisher(interaction::Simulation& sim, const wire::Participant& pp,
                       const std::string& topic_prefix, std::uint32_t full_frame_period,
                       std::function<void(const std::string&)> log);
  ~DeformationPublisher();
  DeformationPublisher(const DeformationPublisher&) = delete;
  DeformationPublisher& operator=(const DeformationPublisher&) = delete;

  // The field thread (`on_start` runs first on it: thread name and priority). Errors end the
  // thread and go to `on_error`.
  void start(std::function<void()> on_start, std::function<void(const std::exception&)> on_error);
  void stop();

  // Step thread, at the viewer rate: a frame of the last step unless no viewer is matched or the
  // field thread is still busy (skipped).
  void tick(std::uint64_t step, std::int64_t now_ns);
  // Step thread, once per status period: the next frame also measures the largest strain;
  // returns the strain measured since the last call (-1: none, no viewer matched).
  double take_max_strain();

  // For tests: waits (at most timeout_ms) until the field thread is idle; true when it is.
  bool wait_idle(int timeout_ms) const;
  void dispose_all();
  std::uint32_t matched_viewers() const { return last_matched_viewers_; }
  const DeformationCounters& counters() const { return counters_; }

 private:
  void field_loop();
  void encode_and_write(std::uint64_t step, std::int64_t now_ns, bool strain);

  interaction::Simulation& sim_;
  std::function<void(const std::string&)> log_;
  wire::Topic<neurosim_Deformation> topic_;
  wire::Writer<neurosim_Deformation> writer_;
  std::vector<wire::DeformationEncoder> encoders_;
  std::vector<wire::Sample<neurosim_Deformation>> out_;
  std::vector<bool> written_;
  std::vector<Eigen::VectorXd> u_m_;  // per mesh, 3N, unit m
  DeformationCounters counters_;
  std::uint32_t last_matched_viewers_{0};    // step thread
  std::atomic<bool> full_frame_pending_{false};  // a new viewer matched: next frames FULL
  std::atomic<bool> strain_due_{false};
  std::atomic<double> max_strain_{-1.0};
  // Field worker handshake: the step thread posts a job only when the worker is idle.
  std::atomic<bool> busy_{false};
  interaction::FieldSnapshot snapshot_;  // written by the step thread while the worker is idle
  mutable std::mutex m_;
  std::condition_variable cv_;
  bool job_{false}, stopping_{false}, job_strain_{false};
  std::uint64_t job_step_{0};
  std::int64_t job_time_ns_{0};
  std::thread thread_;
};

}  // namespace neurosim::service
