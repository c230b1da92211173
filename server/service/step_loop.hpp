// The step thread (docs/ARCHITECTURE.md "Threads"): when a pose arrives (event step mode, at most
// max_step_rate_factor × the scene rate) or one period after the last step, the newest pose of
// every station becomes a ToolPose (the tool frame's +z rotated by the quaternion is the shaft
// axis; its station is the slot, so with rigid obstacles the step holds it outside the bone by the
// slot's proxy in the Simulation), all tools are stepped together (interaction::Simulation::step)
// and each station gets its ContactModel (with the proxy's planes).
//
// A step that throws for the stations' input is contained: the stations whose pose alone makes
// the step throw are reset (their pose dropped, a zero-force ContactModel flagged rejected, no
// step for them for a hold-off), the others are stepped again without them, and the server
// keeps serving. The failure is logged with the station and the error.
#pragma once

#include "idl/wire/dds.hpp"
#include "server/interaction/simulation.hpp"
#include "server/service/station_admission.hpp"

#include <semaphore.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace neurosim::service {

enum class StepMode { kEvent, kClock };
const char* step_mode_name(StepMode m);

// Where the ContactModel samples go (the server's DDS writer; a recorder in tests).
class ContactModelSink {
 public:
  virtual ~ContactModelSink() = default;
  virtual void write(const neurosim_ContactModel& m) = 0;
  virtual void dispose(const neurosim_ContactModel& key) = 0;
};

struct StepLoopDef {
  std::int64_t period_ns{1000000};     // the scene's step period, unit ns
  StepMode mode{StepMode::kEvent};
  double max_step_rate_factor{2.0};    // event mode: steps at most this × the scene rate, [1, 100]
  // A station whose pose made a step throw is not stepped again for this long, unit ns.
  std::int64_t step_failure_holdoff_ns{100000000};
  void validate() const;               // throws std::invalid_argument naming the field
};

struct StepLoopCounters {
  std::atomic<std::uint64_t> steps{0}, deadline_misses{0}, steps_on_sample{0}, steps_on_deadline{0},
      step_failures{0};  // stations reset because their pose made the step throw
};

class StepLoop {
 public:
  StepLoop(StepLoopDef def, interaction::Simulation& sim, StationAdmission& stations,
           ContactModelSink& out, std::function<void(const std::string&)> log);
  ~StepLoop();
  StepLoop(const StepLoop&) = delete;
  StepLoop& operator=(const StepLoop&) = delete;

  // Hooks of the step thread: after each step (inside its measured time: the deformation tick)
  // and after its time was taken (t0, t1 monotonic ns: the status).
  std::function<void(std::uint64_t step)> after_step;
  std::function<void(std::int64_t t0_ns, std::int64_t t1_ns)> after_timing;

  // Event mode: a pose was handed to a slot (the DDS thread; never blocks).
  void wake();
  // The step thread: runs until `running` turns false (stop() wakes it).
  void run(const std::atomic<bool>& running);
  void stop();
  // One step for every station's newest pose (the step thread; tests call it directly).
  void step_once();
  // Disposes every ContactModel instance written (the server is leaving).
  void dispose_all();

  const StepLoopCounters& counters() const { return counters_; }
  std::size_t num_slots() const { return slots_.size(); }

 private:
  struct SlotStep {  // step thread only
    bool joined{false};
    bool has_pose{false};
    bool model_written{false};
    std::int64_t hold_until_ns{0};  // reset after a failed step: not stepped before this
  };
  bool wait_for_sample(std::int64_t deadline_ns);
  void retire(std::size_t i);
  bool try_step(std::size_t n, const std::string** error);
  void contain_failure(std::size_t& n, const std::string& error);
  void write_model(std::size_t slot, const interaction::ToolContact* c, std::uint64_t step, std::int64_t now_ns);

  StepLoopDef def_;
  interaction::Simulation& sim_;
  StationAdmission& stations_;
  std::vector<StationSlot>& slots_;
  ContactModelSink& out_;
  std::function<void(const std::string&)> log_;
  StepLoopCounters counters_;
  sem_t wake_;

  // State of the step thread (sized once: no allocation per step).
  std::vector<SlotStep> slot_step_;
  std::vector<wire::Sample<neurosim_ContactModel>> models_out_;  // one per slot
  std::vector<std::vector<interaction::ToolPose>> poses_by_count_;  // [n] has n poses
  std::vector<std::vector<interaction::ToolContact>> contacts_by_count_;
  std::vector<int> slot_of_pose_;
  std::vector<interaction::ToolPose> all_poses_;  // every station's pose of this step
  std::vector<int> all_slots_;
  std::string step_error_;
  // The step's time: the newest source time of its poses, from the first one seen (unit ns), so
  // a replay of the stations' recordings steps a viscoelastic body through the same times.
  std::int64_t time_origin_ns_{0};
  bool time_origin_set_{false};
  double step_time_s_{0.0};
};

}  // namespace neurosim::service
